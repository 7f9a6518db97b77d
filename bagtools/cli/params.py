"""Option types shared by several commands."""

from __future__ import annotations

import math

import click

from bagtools.limits import MAX_MAP_ORIGIN_M


#: How far from the robot base a laser can be mounted (m): farther is a typo or damage, and would size grids by it.
MAX_SCAN_FRAME_OFFSET_M = 100.0


def _xy_yaw(value: str) -> tuple[float, float, float]:
    """``X,Y,YAW`` as three floats (click.BadParameter when it is not three numbers)."""
    try:
        x, y, yaw = (float(v) for v in value.split(","))
    except ValueError:
        raise click.BadParameter(f"expected X,Y,YAW (metres, metres, radians), got {value!r}") from None
    return x, y, yaw


def initial_pose(ctx: click.Context, param: click.Parameter, value: str | None) -> tuple[float, float, float] | None:
    """``--initial-pose X,Y,YAW`` (metres, metres, radians, map frame) as a tuple, or None."""
    if value is None:
        return None
    pose = _xy_yaw(value)
    if not all(math.isfinite(v) for v in pose) or max(abs(pose[0]), abs(pose[1])) > MAX_MAP_ORIGIN_M:
        raise click.BadParameter(f"expected three finite numbers, X and Y within {MAX_MAP_ORIGIN_M:g} m of the map's "
                                 f"origin, got {value!r}")
    return pose


def scan_frame_offset(ctx: click.Context, param: click.Parameter, value: str | None) -> tuple[float, float, float] | None:
    """``--scan-frame-offset X,Y,YAW`` (metres, metres, radians) as a tuple, or None."""
    if value is None:
        return None
    x, y, yaw = _xy_yaw(value)
    if not all(math.isfinite(v) for v in (x, y, yaw)) or max(abs(x), abs(y)) > MAX_SCAN_FRAME_OFFSET_M:
        raise click.BadParameter(f"expected a laser on the robot: X and Y finite and within "
                                 f"{MAX_SCAN_FRAME_OFFSET_M:g} m of the base, YAW finite, got {value!r}")
    return (x, y, yaw)


SCAN_FRAME_OFFSET_HELP = "Laser pose on the robot base [m, m, rad] when tf lacks (or has a wrong) base -> laser transform."


def cell_size(cell_size_m: float | None, cells_per_metre: float | None, resolution: float | None,
              resolution_in_metres: bool) -> tuple[float, str | None]:
    """(the map cell side (m), the old spelling's note or None) of ``--cell-size``/``--cells-per-metre``/
    ``--resolution`` (see :func:`bagtools.grid.options.map_cell_size`): two of them is a usage error. The caller
    says the note once the run has succeeded (a failure stays one line)."""
    from bagtools.grid.options import cell_size_options_given, map_cell_size

    given = cell_size_options_given(cell_size_m, cells_per_metre, resolution)
    if len(given) > 1:
        raise click.UsageError(f"give one of {' and '.join(given)}: each sets the map's cell size")
    return map_cell_size(cell_size_m, cells_per_metre, resolution, resolution_in_metres)
