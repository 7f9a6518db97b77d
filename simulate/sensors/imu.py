"""IMU model of the TurtleBot3 Waffle, as Gazebo's IMU sensor reports it in ``imu_link``.

Settings from the ``tb3_imu`` sensor of ROBOTIS' ``turtlebot3_gazebo/models/turtlebot3_waffle``:
200 Hz, Gaussian noise with sd 2e-4 rad/s on each angular velocity axis and 1.7e-2 m/s^2 on
each linear acceleration axis. The model sets no orientation noise, so, as in Gazebo, the
orientation is the true one (the heading of imu_link in the world, roll = pitch = 0 on the
flat floor); covariances are the noise variances (orientation: 0, exact).

Kinematics: imu_link sits above the wheel axis centre (x = y = 0 in base_footprint), so for
the planar motion (v, w) it measures angular velocity (0, 0, w) and specific force
(dv/dt, v w, g): the forward acceleration, the centripetal term and gravity's reaction
(+g up, as a resting accelerometer reads). The motion holds (v, w) per 1/30 s step; the
forward acceleration in a step is the change from the previous step's v spread over it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bagtools_simulate.robot.controller import Motion

GRAVITY_MPS2 = 9.8  # Gazebo's default world gravity, as in the TurtleBot3 worlds


@dataclass(frozen=True)
class ImuSamples:
    """K IMU readings in imu_link: orientation quaternions (K, 4) x, y, z, w; angular velocity (K, 3) rad/s;
    linear acceleration (K, 3) m/s^2."""

    quat_xyzw: np.ndarray
    angular_velocity_radps: np.ndarray
    linear_acceleration_mps2: np.ndarray


@dataclass(frozen=True)
class Imu:
    """Gazebo-like IMU: rate in Hz, white-noise sd per axis."""

    rate_hz: float = 200.0
    gyro_noise_sd_radps: float = 2e-4
    accel_noise_sd_mps2: float = 1.7e-2
    gravity_mps2: float = GRAVITY_MPS2

    @property
    def orientation_covariance(self) -> np.ndarray:
        """Row-major 3x3 covariance of the orientation (rad^2): zero, the orientation is exact."""
        return np.zeros(9)

    @property
    def angular_velocity_covariance(self) -> np.ndarray:
        """Row-major 3x3 covariance of the angular velocity ((rad/s)^2)."""
        return np.diag(np.full(3, self.gyro_noise_sd_radps**2)).ravel()

    @property
    def linear_acceleration_covariance(self) -> np.ndarray:
        """Row-major 3x3 covariance of the linear acceleration ((m/s^2)^2)."""
        return np.diag(np.full(3, self.accel_noise_sd_mps2**2)).ravel()

    def samples(self, motion: Motion, t_s: np.ndarray, rng: np.random.Generator | None) -> ImuSamples:
        """Readings at times ``t_s`` (K,) s since the start of ``motion``; ``rng`` None gives exact readings.

        Draws exactly 6 K normals when noise is on (angular velocity then acceleration).
        """
        t_s = np.asarray(t_s, dtype=np.float64)
        n_steps = len(motion.v_mps)
        k = np.clip(np.floor(t_s / motion.dt_s).astype(np.int64), 0, n_steps - 1)
        yaw = motion.pose_at_offset(t_s)[:, 2]
        v, w = motion.v_mps[k], motion.w_radps[k]
        v_before = np.concatenate(([0.0], motion.v_mps[:-1]))[k]
        gyro = np.zeros((len(t_s), 3))
        gyro[:, 2] = w
        accel = np.column_stack([(v - v_before) / motion.dt_s, v * w, np.full(len(t_s), self.gravity_mps2)])
        if rng is not None:
            gyro += rng.normal(0.0, self.gyro_noise_sd_radps, gyro.shape)
            accel += rng.normal(0.0, self.accel_noise_sd_mps2, accel.shape)
        quat = np.zeros((len(t_s), 4))
        quat[:, 2] = np.sin(0.5 * yaw)
        quat[:, 3] = np.cos(0.5 * yaw)
        return ImuSamples(quat, gyro, accel)
