"""Wheel odometry with systematic and random errors, integrated from simulated encoders.

The true motion turns each wheel by an angle that depends on the robot's *true* wheel radii
and separation; the odometry converts encoder increments back to motion with the *nominal*
(URDF) values, so calibration errors give systematic drift, and per-step slip noise gives a
random walk. ``none`` reproduces the true motion (zero drift).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bagtools.errors import BagtoolsError
from bagtools_simulate.robot.controller import Motion
from bagtools_simulate.robot.kinematics import integrate_increments
from bagtools_simulate.robot.waffle import ENCODER_TICKS_PER_REV, WHEEL_RADIUS_M, WHEEL_SEPARATION_M


@dataclass(frozen=True)
class OdomNoise:
    """Standard deviations of relative errors: wheel radii and separation (drawn once), wheel slip (per step)."""

    radius_sd: float
    separation_sd: float
    slip_sd: float
    quantize: bool


ODOM_NOISE_LEVELS: dict[str, OdomNoise] = {
    "none": OdomNoise(0.0, 0.0, 0.0, quantize=False),
    # Borenstein's UMBmark reports wheel-diameter mismatches of a few tenths of a percent and
    # effective wheelbase errors of one to a few percent on uncalibrated differential drives.
    "realistic": OdomNoise(0.003, 0.015, 0.02, quantize=True),
    "high": OdomNoise(0.01, 0.05, 0.06, quantize=True),
}


@dataclass(frozen=True)
class Odometry:
    """Odometry of base_footprint in the odom frame (origin = start pose).

    ``poses`` (N+1, 3) [x, y, yaw] at the step boundaries; ``v_mps``/``w_radps`` (N,) the measured
    twist over each step (in base_footprint); ``wheel_left_rad``/``wheel_right_rad`` (N+1,) the
    encoder angles the odometry integrated (wheel_left_joint/wheel_right_joint positions, 0 at
    the start); the calibration factors actually drawn.
    """

    poses: np.ndarray
    v_mps: np.ndarray
    w_radps: np.ndarray
    radius_scale_left: float
    radius_scale_right: float
    separation_scale: float
    wheel_left_rad: np.ndarray
    wheel_right_rad: np.ndarray


def wheel_odometry(motion: Motion, level: str, rng: np.random.Generator) -> Odometry:
    """Simulate encoders for ``motion`` and integrate odometry with noise ``level`` (none|realistic|high)."""
    if level not in ODOM_NOISE_LEVELS:
        raise BagtoolsError(f"unknown odometry noise {level!r} (choose from {', '.join(ODOM_NOISE_LEVELS)})")
    noise = ODOM_NOISE_LEVELS[level]
    # Calibration errors: drawn once per bag, clipped to two standard deviations.
    z = np.clip(rng.standard_normal(3), -2.0, 2.0)
    scale_l, scale_r = 1.0 + noise.radius_sd * z[:2]
    scale_b = 1.0 + noise.separation_sd * z[2]
    n = len(motion.v_mps)
    ds_true = motion.v_mps * motion.dt_s
    dyaw_true = motion.w_radps * motion.dt_s
    half_b_true = 0.5 * WHEEL_SEPARATION_M * scale_b
    # Wheel rotation (rad) the true motion needs, with the true wheel geometry.
    dphi_r = (ds_true + dyaw_true * half_b_true) / (WHEEL_RADIUS_M * scale_r)
    dphi_l = (ds_true - dyaw_true * half_b_true) / (WHEEL_RADIUS_M * scale_l)
    if noise.slip_sd > 0.0:
        slip = noise.slip_sd * rng.standard_normal((2, n))
        dphi_r = dphi_r * (1.0 + slip[0])
        dphi_l = dphi_l * (1.0 + slip[1])
    if noise.quantize:
        rad_per_tick = 2.0 * np.pi / ENCODER_TICKS_PER_REV
        ticks_r = np.floor(np.concatenate(([0.0], np.cumsum(dphi_r))) / rad_per_tick)
        ticks_l = np.floor(np.concatenate(([0.0], np.cumsum(dphi_l))) / rad_per_tick)
        dphi_r, dphi_l = np.diff(ticks_r) * rad_per_tick, np.diff(ticks_l) * rad_per_tick
    if level == "none":
        ds, dyaw = ds_true, dyaw_true  # exact: avoid round-off from the wheel round trip
    else:
        ds_r, ds_l = dphi_r * WHEEL_RADIUS_M, dphi_l * WHEEL_RADIUS_M
        ds, dyaw = 0.5 * (ds_r + ds_l), (ds_r - ds_l) / WHEEL_SEPARATION_M
    poses = integrate_increments((0.0, 0.0, 0.0), ds, dyaw)
    wheel_left = np.concatenate(([0.0], np.cumsum(dphi_l)))
    wheel_right = np.concatenate(([0.0], np.cumsum(dphi_r)))
    return Odometry(poses, ds / motion.dt_s, dyaw / motion.dt_s, float(scale_l), float(scale_r), float(scale_b),
                    wheel_left, wheel_right)

