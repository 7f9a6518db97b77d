"""Differential-drive kinematics: exact integration of constant (v, w) over a step.

Poses are (x, y, yaw) in metres and radians; v in m/s, w in rad/s, dt in seconds.
"""

from __future__ import annotations

import numpy as np


def arc_increments(ds_m: np.ndarray, dyaw_rad: np.ndarray, yaw_start_rad: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Displacement (dx, dy) of a constant-curvature arc of length ``ds_m`` turning by ``dyaw_rad``.

    ``yaw_start_rad`` is the heading at the start of each arc. All arrays broadcast; exact for
    constant v and w (the chord has length ds*sinc(dyaw/2) along the mid heading).
    """
    chord = ds_m * np.sinc(dyaw_rad / (2.0 * np.pi))
    mid = yaw_start_rad + 0.5 * dyaw_rad
    return chord * np.cos(mid), chord * np.sin(mid)


def integrate_increments(start_xyyaw: tuple[float, float, float], ds_m: np.ndarray, dyaw_rad: np.ndarray) -> np.ndarray:
    """Poses (N+1, 3) [x, y, yaw] after each of N arc increments, starting at ``start_xyyaw``.

    Vectorized with cumulative sums: yaw is not wrapped (continuous heading).
    """
    ds_m = np.asarray(ds_m, dtype=np.float64)
    dyaw_rad = np.asarray(dyaw_rad, dtype=np.float64)
    x0, y0, yaw0 = start_xyyaw
    yaw = yaw0 + np.concatenate(([0.0], np.cumsum(dyaw_rad)))
    dx, dy = arc_increments(ds_m, dyaw_rad, yaw[:-1])
    poses = np.empty((len(ds_m) + 1, 3))
    poses[:, 0] = x0 + np.concatenate(([0.0], np.cumsum(dx)))
    poses[:, 1] = y0 + np.concatenate(([0.0], np.cumsum(dy)))
    poses[:, 2] = yaw
    return poses


def pose_at(pose_xyyaw: np.ndarray, v_mps: float, w_radps: float, dt_s: float) -> np.ndarray:
    """The pose [x, y, yaw] reached from ``pose_xyyaw`` driving (v, w) for ``dt_s`` seconds."""
    dx, dy = arc_increments(np.float64(v_mps * dt_s), np.float64(w_radps * dt_s), np.float64(pose_xyyaw[2]))
    return np.array([pose_xyyaw[0] + dx, pose_xyyaw[1] + dy, pose_xyyaw[2] + w_radps * dt_s])


def wrap_angle(a: np.ndarray | float) -> np.ndarray | float:
    """Angles wrapped to [-pi, pi)."""
    return (np.asarray(a) + np.pi) % (2.0 * np.pi) - np.pi
