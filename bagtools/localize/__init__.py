"""Localization in a map the robot already has (issue #26; the first part: the global search).

- :class:`GlobalLocalizer`: where one scan can be in a nav2 map, anywhere and at
  any heading, with no initial pose: the distinct places that match it, best first.
"""

from bagtools.localize.global_search import GlobalLocalizer, Hypothesis

__all__ = ["GlobalLocalizer", "Hypothesis"]
