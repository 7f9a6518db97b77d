"""The global search: a scan matched against a whole map at every heading, with no initial pose.

The map's occupied cells are the reference of the correlative branch and bound
(:func:`~bagtools.scan_matching.match_scans_grid_peaks`), searched over the map's whole
extent and a full turn on a ``coarse_m`` raster (10 cm; coarser where the
branch and bound's pyramids, the map padded by the window, would exceed
:data:`~bagtools.scan_matching.correlative.MAX_RASTER_CELLS`: 12 cm for 100 m x 100 m,
while at the map's own 5 cm a 50 m map already does), with one scan point per
coarse cell. Its distinct peaks,
``min_ratio`` of the best or more and ``separation`` apart, are each refined on
a ``fine_m`` raster in a window of ``REFINE_STEPS`` coarse steps. A map that repeats itself
(a symmetric room, a corridor) gives several hypotheses of nearly equal score:
the caller keeps them until later scans decide.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from bagtools.grid import Nav2Map
from bagtools.scan_matching import CorrelativeReference, match_scans_grid, match_scans_grid_peaks, voxel_subsample
from bagtools.scan_matching.correlative import MAX_RASTER_CELLS
from bagtools.scan_matching.window_search import MAX_DEPTH

#: Hypotheses closer than this (m, rad) are one place.
SEPARATION = (1.0, 0.3)
#: The global search turns the scan in steps that move a point this far out (m) by one coarse cell; the
#: refinement then turns it in the fine steps its farthest point needs.
REACH_M = 10.0
#: Each coarse peak is refined within this many coarse steps (translation and rotation) of it: along a corridor the
#: coarse raster's best can lie a few cells from the place.
REFINE_STEPS = 4.0


def coarse_cell_for(extent_m: np.ndarray) -> float:
    """The finest raster cell (m) at which a search over a map of ``extent_m`` (2,) fits the branch and bound's
    pyramids: MAX_DEPTH + 1 levels, each the map padded by the window on both sides (about 3x the map a side)."""
    w, h = (float(v) for v in extent_m)
    levels = MAX_DEPTH + 1
    # levels * (3 w / r + 4) * (3 h / r + 4) <= 0.9 * MAX_RASTER_CELLS, solved for r (the + 4 as 1 cell of slack)
    return 3.0 * math.sqrt(levels * max(w, 1.0) * max(h, 1.0) / (0.9 * MAX_RASTER_CELLS)) * 1.05


@dataclass(frozen=True)
class Hypothesis:
    """A place the scan matches: ``pose`` [x, y, theta] (m, m, rad) of the scan's frame in the map frame
    (``p_map = R(theta) p_scan + [x, y]``), ``score`` in [0, 1] (the fine raster's)."""

    pose: np.ndarray
    score: float


class GlobalLocalizer:
    """Where a scan can be in a map (see the module docstring).

    Args:
        map_points: (N, 2) occupied places of the map, map frame, metres (e.g. :meth:`Nav2Map.occupied_points`).
        coarse_m: raster cell of the global search (m).
        fine_m: raster cell of the refinement (m).
    """

    def __init__(self, map_points: np.ndarray, coarse_m: float = 0.1, fine_m: float = 0.05) -> None:
        pts = np.asarray(map_points, dtype=np.float64).reshape(-1, 2)
        pts = pts[np.isfinite(pts).all(axis=1)]
        if len(pts) < 5:
            raise ValueError(f"a map needs at least 5 occupied places to localize in, got {len(pts)}")
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        coarse_m = max(coarse_m, coarse_cell_for(hi - lo))
        self.coarse = CorrelativeReference.from_points(pts, resolution_m=coarse_m)
        self.fine = CorrelativeReference.from_points(pts, resolution_m=fine_m)
        self.centre = 0.5 * (lo + hi)
        self.half_extent = np.maximum(0.5 * (hi - lo), coarse_m)

    @classmethod
    def from_map(cls, nav2_map: Nav2Map, coarse_m: float = 0.1) -> GlobalLocalizer:
        """From a nav2 map, refined at the map's own resolution."""
        return cls(nav2_map.occupied_points(), coarse_m=max(coarse_m, nav2_map.resolution_m),
                   fine_m=nav2_map.resolution_m)

    def search(self, scan_points: np.ndarray, max_hypotheses: int = 4, min_ratio: float = 0.8,
               min_score: float = 0.3) -> list[Hypothesis]:
        """The distinct places (at most ``max_hypotheses``, best first) where ``scan_points`` ((M, 2), the scan's
        frame, m) match the map with a coarse score of ``min_score`` and ``min_ratio`` of the best; [] if none."""
        scan = np.asarray(scan_points, dtype=np.float64).reshape(-1, 2)
        angular_step = self.coarse.resolution_m / REACH_M
        thinned = voxel_subsample(scan[np.isfinite(scan).all(axis=1)], self.coarse.resolution_m)  # one per coarse cell
        peaks = match_scans_grid_peaks(thinned, self.coarse, initial_pose=(self.centre[0], self.centre[1], 0.0),
                                       search_range=(float(self.half_extent[0]), float(self.half_extent[1]), math.pi),
                                       angular_resolution_rad=angular_step, max_peaks=max_hypotheses,
                                       min_ratio=min_ratio, separation=SEPARATION, min_score=min_score)
        step = REFINE_STEPS * self.coarse.resolution_m
        found = []
        for peak in peaks:
            fine = match_scans_grid(scan, self.fine, initial_pose=peak.pose,
                                    search_range=(step, step, REFINE_STEPS * angular_step))
            best = fine if fine.ok else peak
            found.append(Hypothesis(np.asarray(best.pose, dtype=np.float64), float(best.score)))
        return sorted(found, key=lambda h: -h.score)
