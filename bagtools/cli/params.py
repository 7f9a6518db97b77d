"""Option types shared by several commands."""

from __future__ import annotations

import click


def scan_frame_offset(ctx: click.Context, param: click.Parameter, value: str | None) -> tuple[float, float, float] | None:
    """``--scan-frame-offset X,Y,YAW`` (metres, metres, radians) as a tuple, or None."""
    if value is None:
        return None
    try:
        x, y, yaw = (float(v) for v in value.split(","))
    except ValueError:
        raise click.BadParameter(f"expected X,Y,YAW (metres, metres, radians), got {value!r}") from None
    return (x, y, yaw)


SCAN_FRAME_OFFSET_HELP = "Laser pose on the robot base [m, m, rad] when tf lacks (or has a wrong) base -> laser transform."
