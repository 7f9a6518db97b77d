"""What ``bagtools grid`` builds and how: the options of the grid-mapping pipeline."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from bagtools.errors import BagtoolsError

POSES_TF = "tf"
POSES_GROUND_TRUTH = "ground-truth"

MAX_GRID_CELLS = 100_000_000
"""The largest grid the pipeline builds (10^8 cells, 400 MB of float32 log-odds): a bad pose must not allocate more."""
MIN_RESOLUTION = 0.1
MAX_RESOLUTION = 1000.0
"""Cells per metre accepted by --resolution (cells of 10 m to 1 mm)."""
DEFAULT_CELL_SIZE_M = 0.05
"""The map cell side of grid and slam when none is given (m)."""


def cell_size_options_given(cell_size_m: float | None, cells_per_metre: float | None,
                            resolution: float | None) -> list[str]:
    """The names of the cell-size options given (not None), in the order --cell-size, --cells-per-metre,
    --resolution."""
    return [name for name, value in (("--cell-size", cell_size_m), ("--cells-per-metre", cells_per_metre),
                                     ("--resolution", resolution)) if value is not None]


def map_cell_size(cell_size_m: float | None, cells_per_metre: float | None, resolution: float | None,
                  resolution_in_metres: bool) -> tuple[float, str | None]:
    """(the map cell side in metres, a one-line note or None) from ``--cell-size`` (m), ``--cells-per-metre`` or the
    old ``--resolution``, which ``grid`` reads as cells per metre (MATLAB's) and ``slam`` as metres (nav2's:
    ``resolution_in_metres``); at most one of them may be given (BagtoolsError). The note, for the old spelling,
    says what it was read as."""
    given = cell_size_options_given(cell_size_m, cells_per_metre, resolution)
    if len(given) > 1:
        raise BagtoolsError(f"give one of {' and '.join(given)}: each sets the map's cell size")
    note = None
    if cells_per_metre is not None or (resolution is not None and not resolution_in_metres):
        per_metre = cells_per_metre if cells_per_metre is not None else resolution
        if not (math.isfinite(per_metre) and MIN_RESOLUTION <= per_metre <= MAX_RESOLUTION):
            raise BagtoolsError(f"{given[0]} must be between {MIN_RESOLUTION:g} and {MAX_RESOLUTION:g} cells per metre "
                                f"(cells of 10 m to 1 mm), got {per_metre}")
        side = 1.0 / per_metre
    else:
        side = DEFAULT_CELL_SIZE_M if not given else cell_size_m if cell_size_m is not None else resolution
        if not (math.isfinite(side) and 1.0 / MAX_RESOLUTION <= side <= 1.0 / MIN_RESOLUTION):
            raise BagtoolsError(f"{given[0] if given else 'the cell size'} must be a cell side between "
                                f"{1.0 / MAX_RESOLUTION:g} and {1.0 / MIN_RESOLUTION:g} metres, got {side}")
    if resolution is not None:
        unit = "metres per cell (nav2's)" if resolution_in_metres else "cells per metre (MATLAB's)"
        note = (f"--resolution {resolution:g} read as {unit}: a cell of {side:g} m; --cell-size {side:g} says so in "
                "every command")
    return side, note


@dataclass(frozen=True)
class GridMapOptions:
    """Options of :class:`~bagtools.commands.grid.GridMapPipeline`.

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

    @classmethod
    def from_params(cls, p: Mapping[str, Any]) -> GridMapOptions:
        """The options ``bagtools grid`` was given: its click parameters by name (the command and its batch job
        build them here, so the two cannot differ)."""
        side, _ = map_cell_size(p["cell_size"], p["cells_per_metre"], p["resolution"], resolution_in_metres=False)
        return cls(topic=p["topic"], frame=cls.default_frame(p["poses"]) if p["frame"] is None else p["frame"],
                   poses=p["poses"], resolution=1.0 / side, max_range_m=p["max_range"], base_frame=p["base_frame"],
                   scan_frame_offset=p["scan_frame_offset"])

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
