"""2D Normal Distributions Transform scan matching (Biber and Strasser, IROS 2003).

``match_scans(current, reference)`` returns the pose [x, y, theta] of the current
scan's frame in the reference scan's frame (``p_ref = R(theta) p_cur + [x, y]``)
and MATLAB ``matchScans``-style stats; ``match_scans_ranges`` takes ranges and
angles. Build an :class:`NdtReference` once to match several scans against it.
"""

from bagtools.ndt.grid import NdtReference
from bagtools.ndt.matcher import MIN_SCAN_POINTS, NdtResult, match_scans, match_scans_ranges, ranges_to_points

__all__ = ["MIN_SCAN_POINTS", "NdtReference", "NdtResult", "match_scans", "match_scans_ranges", "ranges_to_points"]
