"""Localization in a map the robot already has (``bagtools localize``, issue #26).

- :class:`GlobalLocalizer`: where one scan can be in a nav2 map, anywhere and at
  any heading, with no initial pose: the distinct places that match it, best first.
- :class:`MapLocalizer`: the scans of a bag tracked in the map: searched for,
  confirmed among look-alike places, tracked, lost and recovered.
- :func:`smooth_track`: the tracked poses smoothed with the laser odometry (a GTSAM pose graph), and the
  places the robot came back to tied by their scans (:func:`revisit_factors`), the map matches held where
  they put the base less their offset from it (:func:`map_offset`).
- :class:`LocalizePipeline`: a bag in a nav2 map, with the bag's own localizer
  (AMCL's map -> odom) and ground truth compared; :func:`write_localize` its files.
"""

from bagtools.commands.localize.global_search import GlobalLocalizer, Hypothesis
from bagtools.commands.localize.pipeline import LocalizeOptions, LocalizePipeline, LocalizeResult
from bagtools.commands.localize.smoother import map_offset, revisit_factors, smooth_track
from bagtools.commands.localize.tracker import MapLocalizer
from bagtools.commands.localize.writer import LOCALIZE_FILES, write_localize

__all__ = ["LOCALIZE_FILES", "GlobalLocalizer", "Hypothesis", "LocalizeOptions", "LocalizePipeline", "LocalizeResult",
           "MapLocalizer", "map_offset", "revisit_factors", "smooth_track", "write_localize"]
