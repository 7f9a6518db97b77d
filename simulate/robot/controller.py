"""A regulated pure-pursuit controller with acceleration limits, driving the robot along a route.

The controller runs at the odometry rate; within each step the commanded (v, w) is constant,
so the true motion is integrated exactly (:mod:`bagtools_simulate.robot.kinematics`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bagtools.errors import BagtoolsError
from bagtools_simulate.robot.kinematics import integrate_increments, wrap_angle
from bagtools_simulate.robot.waffle import MAX_ANGULAR_RADPS, MAX_LINEAR_MPS

LOOKAHEAD_M = 0.3
ROTATE_TO_HEADING_RAD = 0.785  # nav2 RPP rotate_to_heading_min_angle
MIN_TURN_RADIUS_FOR_FULL_SPEED_M = 0.9  # nav2 RPP regulated_linear_scaling_min_radius
MIN_REGULATED_SPEED_MPS = 0.05


@dataclass(frozen=True)
class Limits:
    """Speed (m/s, rad/s) and acceleration (m/s^2, rad/s^2) limits of the controller."""

    max_linear_mps: float = MAX_LINEAR_MPS
    max_angular_radps: float = MAX_ANGULAR_RADPS
    accel_linear_mps2: float = 0.5
    accel_angular_radps2: float = 2.0

    def check(self) -> None:
        """Raise BagtoolsError unless 0 < limits <= the Waffle's maxima."""
        if not 0.0 < self.max_linear_mps <= MAX_LINEAR_MPS:
            raise BagtoolsError(f"--max-linear must be in (0, {MAX_LINEAR_MPS}] m/s, got {self.max_linear_mps}")
        if not 0.0 < self.max_angular_radps <= MAX_ANGULAR_RADPS:
            raise BagtoolsError(f"--max-angular must be in (0, {MAX_ANGULAR_RADPS}] rad/s, got {self.max_angular_radps}")


@dataclass(frozen=True)
class Motion:
    """The driven motion: per step k (0..N-1) the command (v, w) held from t_k to t_k+dt.

    ``poses`` (N+1, 3) are the true poses [x, y, yaw] of base_footprint in map at t_0..t_N.
    """

    dt_s: float
    v_mps: np.ndarray
    w_radps: np.ndarray
    poses: np.ndarray

    def pose_at_offset(self, t_s: np.ndarray) -> np.ndarray:
        """True poses (K, 3) at times ``t_s`` (seconds since t_0, within [0, N*dt]), exact within steps."""
        t_s = np.asarray(t_s, dtype=np.float64)
        k = np.clip(np.floor(t_s / self.dt_s).astype(int), 0, len(self.v_mps) - 1)
        tau = t_s - k * self.dt_s
        start = self.poses[k]
        yaw0 = start[:, 2]
        dyaw = self.w_radps[k] * tau
        chord = self.v_mps[k] * tau * np.sinc(dyaw / (2.0 * np.pi))
        mid = yaw0 + 0.5 * dyaw
        return np.column_stack([start[:, 0] + chord * np.cos(mid), start[:, 1] + chord * np.sin(mid), yaw0 + dyaw])


def drive(path_xy: np.ndarray, start_xyyaw: tuple[float, float, float], n_steps: int, dt_s: float, limits: Limits) -> Motion:
    """Follow the polyline ``path_xy`` (M, 2, dense) from ``start_xyyaw`` for ``n_steps`` steps of ``dt_s`` s.

    Regulated pure pursuit: lookahead point on the path, curvature 2 sin(alpha)/L, speed lowered
    on tight turns, rotation in place when the heading error is large; then linear and angular
    acceleration limits. The loop over steps is inherent (each command depends on the last pose).
    """
    limits.check()
    if len(path_xy) < 2:
        raise BagtoolsError("route path has fewer than two points")
    seg_len = np.linalg.norm(np.diff(path_xy, axis=0), axis=1)
    s_path = np.concatenate(([0.0], np.cumsum(seg_len)))
    mean_spacing = max(float(s_path[-1]) / (len(path_xy) - 1), 1e-6)
    window_back = int(0.2 / mean_spacing) + 1
    window_ahead = int(1.0 / mean_spacing) + 2
    look_n = max(1, int(round(LOOKAHEAD_M / mean_spacing)))

    v_cmd = np.zeros(n_steps)
    w_cmd = np.zeros(n_steps)
    x, y, yaw = (float(c) for c in start_xyyaw)
    v = w = 0.0
    idx = 0
    dv_max = limits.accel_linear_mps2 * dt_s
    dw_max = limits.accel_angular_radps2 * dt_s
    last = len(path_xy) - 1
    for k in range(n_steps):
        lo, hi = max(0, idx - window_back), min(last + 1, idx + window_ahead)
        d2 = (path_xy[lo:hi, 0] - x) ** 2 + (path_xy[lo:hi, 1] - y) ** 2
        idx = max(idx, lo + int(np.argmin(d2)))
        target = path_xy[min(idx + look_n, last)]
        dx, dy = target[0] - x, target[1] - y
        alpha = float(wrap_angle(np.arctan2(dy, dx) - yaw))
        dist = max(np.hypot(dx, dy), 1e-6)
        if idx >= last and dist < 0.05:
            v_des = w_des = 0.0
        elif abs(alpha) > ROTATE_TO_HEADING_RAD:
            v_des = 0.0
            # Slow the turn so that it can stop at the heading without overshoot.
            w_des = np.sign(alpha) * min(limits.max_angular_radps, np.sqrt(2.0 * limits.accel_angular_radps2 * abs(alpha)))
        else:
            kappa = 2.0 * np.sin(alpha) / dist
            v_des = limits.max_linear_mps
            radius = 1.0 / abs(kappa) if kappa != 0.0 else np.inf
            if radius < MIN_TURN_RADIUS_FOR_FULL_SPEED_M:
                v_des = max(MIN_REGULATED_SPEED_MPS, v_des * radius / MIN_TURN_RADIUS_FOR_FULL_SPEED_M)
            if abs(kappa) * v_des > limits.max_angular_radps:
                v_des = limits.max_angular_radps / abs(kappa)
            w_des = v_des * kappa
        v = float(min(max(v_des, v - dv_max), v + dv_max))  # clamps on Python floats: np.clip costs ~5 us a call
        w = float(min(max(w_des, w - dw_max), w + dw_max))
        v = min(max(v, -limits.max_linear_mps), limits.max_linear_mps)
        w = min(max(w, -limits.max_angular_radps), limits.max_angular_radps)
        v_cmd[k], w_cmd[k] = v, w
        dyaw = w * dt_s
        chord = v * dt_s * np.sinc(dyaw / (2.0 * np.pi))
        x += chord * np.cos(yaw + 0.5 * dyaw)
        y += chord * np.sin(yaw + 0.5 * dyaw)
        yaw += dyaw
    poses = integrate_increments(tuple(float(c) for c in start_xyyaw), v_cmd * dt_s, w_cmd * dt_s)
    return Motion(dt_s, v_cmd, w_cmd, poses)
