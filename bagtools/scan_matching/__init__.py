"""2D Normal Distributions Transform scan matching (Biber and Strasser, IROS 2003).

``match_scans(current, reference)`` returns the pose [x, y, theta] of the current
scan's frame in the reference scan's frame (``p_ref = R(theta) p_cur + [x, y]``)
and MATLAB ``matchScans``-style stats; ``match_scans_ranges`` takes ranges and
angles. Build an :class:`NdtReference` once to match several scans against it.

``match_scans_grid(current, reference, search_range=...)`` is the search-based
matcher (MATLAB ``matchScansGrid``): correlative scan matching over a window
around an initial pose, by branch and bound on max-pooled likelihood rasters;
same pose convention, returns the best pose of the discretized window with a
score and a covariance. Build a :class:`CorrelativeReference` once to match
many scans against one reference or local map. ``match_scans_grid_peaks`` returns
the window's distinct good poses (for scenes that repeat), best first.
``COVARIANCE_FLOOR`` and ``information_inverse`` turn a match's precision into its
covariance (:mod:`bagtools.scan_matching.covariance`).
"""

from bagtools.scan_matching.correlative import (
    CorrelativeReference, GridMatchResult, match_scans_grid, match_scans_grid_peaks, match_scans_grid_ranges,
    voxel_subsample,
)
from bagtools.scan_matching.covariance import COVARIANCE_FLOOR, information_inverse
from bagtools.scan_matching.grid import NdtReference
from bagtools.scan_matching.matcher import MIN_SCAN_POINTS, NdtResult, match_scans, match_scans_ranges, ranges_to_points

__all__ = [
    "COVARIANCE_FLOOR", "MIN_SCAN_POINTS", "CorrelativeReference", "GridMatchResult", "NdtReference", "NdtResult",
    "information_inverse", "match_scans", "match_scans_grid", "match_scans_grid_peaks", "match_scans_grid_ranges",
    "match_scans_ranges", "ranges_to_points", "voxel_subsample",
]
