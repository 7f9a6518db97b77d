"""What ``bagtools grid`` builds and how: the options of the grid-mapping pipeline."""

from __future__ import annotations

import math
from dataclasses import dataclass

from bagtools.errors import BagtoolsError

POSES_TF = "tf"
POSES_GROUND_TRUTH = "ground-truth"

MAX_GRID_CELLS = 100_000_000
"""The largest grid the pipeline builds (10^8 cells, 400 MB of float32 log-odds): a bad pose must not allocate more."""
MIN_RESOLUTION = 0.1
MAX_RESOLUTION = 1000.0
"""Cells per metre accepted by --resolution (cells of 10 m to 1 mm)."""


@dataclass(frozen=True)
class GridMapOptions:
    """Options of :class:`~bagtools.gridmap.GridMapPipeline`.

    ``poses``: 'tf' (the scan frame's pose in ``frame`` from the bag's tf at each
    scan stamp), 'ground-truth' (the simulator's ``/ground_truth``, in map), or
    the path of a TUM trajectory of the robot base in ``frame``.
    ``resolution``: cells per metre. ``max_range_m``: lowers each scan's
    range_max (None keeps it). ``base_frame``: the robot frame a trajectory
    (TUM) describes; None picks the ``/odom`` child frame, else base_footprint
    or base_link from tf (or the body a bagtools TUM file names).
    ``scan_frame_offset``: (x m, y m, yaw rad) of the laser on the base,
    overriding (or standing in for) tf. ``max_cells``: refuse to build a larger grid.
    """

    topic: str = "/scan"
    frame: str = "map"
    poses: str = POSES_TF
    resolution: float = 20.0
    max_range_m: float | None = None
    base_frame: str | None = None
    scan_frame_offset: tuple[float, float, float] | None = None
    max_cells: int = MAX_GRID_CELLS

    def __post_init__(self) -> None:
        if not (math.isfinite(self.resolution) and MIN_RESOLUTION <= self.resolution <= MAX_RESOLUTION):
            raise BagtoolsError(f"--resolution must be between {MIN_RESOLUTION:g} and {MAX_RESOLUTION:g} cells per metre "
                                f"(cells of 10 m to 1 mm), got {self.resolution}")
        if self.max_range_m is not None and not (math.isfinite(self.max_range_m) and self.max_range_m > 0):
            raise BagtoolsError(f"--max-range must be a positive number of metres, got {self.max_range_m}")
        if not self.frame or self.frame.startswith("/"):
            raise BagtoolsError(f"--frame must be a tf frame id without a leading '/', got {self.frame!r}")
        if not self.poses:
            raise BagtoolsError("--poses must be 'tf', 'ground-truth' or a TUM file")
        if self.poses == POSES_GROUND_TRUTH and self.frame != "map":
            raise BagtoolsError(f"--poses ground-truth gives poses in the map frame; use --frame map, not {self.frame!r}")
        if self.scan_frame_offset is not None and (len(self.scan_frame_offset) != 3
                                                   or not all(math.isfinite(v) for v in self.scan_frame_offset)):
            raise BagtoolsError(f"--scan-frame-offset must be three numbers X,Y,YAW, got {self.scan_frame_offset!r}")
        if self.max_cells <= 0:
            raise BagtoolsError(f"max_cells must be positive, got {self.max_cells}")

    @staticmethod
    def default_frame(poses: str) -> str:
        """The fixed frame to map in when none is given: the frame a bagtools TUM file names, else map."""
        from bagtools.trajectory import read_tum_frames

        named = read_tum_frames(poses) if poses not in (POSES_TF, POSES_GROUND_TRUTH) else None
        return named[0] if named else "map"

    @property
    def poses_kind(self) -> str:
        """'tf', 'ground-truth' or 'tum'."""
        return self.poses if self.poses in (POSES_TF, POSES_GROUND_TRUTH) else "tum"
