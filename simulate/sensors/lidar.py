"""LDS-01 2D lidar model, as the TurtleBot3 Waffle's Gazebo sensor reports it.

Defaults come from the ``hls_lfcd_lds`` ray sensor in ROBOTIS'
``turtlebot3_gazebo/models/turtlebot3_waffle/model.sdf`` (ROS 2): 360 samples
from ``min_angle`` 0 to ``max_angle`` 6.28 rad (so the angle increment is
6.28/359 rad, as ``/scan`` from the simulator shows), range 0.12-3.5 m,
Gaussian range noise with sd 0.01 m. The update rate here is 5 Hz, the
rate the real LDS-01 spins at.

Invalid readings follow what Gazebo's ray sensor does (REP 117): a true
distance at or beyond ``range_max`` (or no hit at all) is ``+inf``; a true
distance at or below ``range_min`` is ``-inf``. Valid readings get the noise
and are then clamped to ``[range_min, range_max]``, as Gazebo clamps them.
(The real ``hls_lfcd_lds_driver`` reports 0.0 for no return instead.)
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from bagtools_simulate.world import World


@dataclass(frozen=True)
class Lidar:
    """A planar scanner. Angles in rad counter-clockwise from the scanner's +x axis."""

    samples: int = 360
    angle_min_rad: float = 0.0
    angle_max_rad: float = 6.28
    range_min_m: float = 0.12
    range_max_m: float = 3.5
    noise_sd_m: float = 0.01
    rate_hz: float = 5.0
    angles_rad: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if self.samples < 1:
            raise ValueError(f"samples must be at least 1, got {self.samples}")
        if not 0.0 <= self.range_min_m < self.range_max_m:
            raise ValueError("need 0 <= range_min_m < range_max_m")
        if self.noise_sd_m < 0.0 or self.rate_hz <= 0.0:
            raise ValueError("noise_sd_m must be >= 0 and rate_hz > 0")
        angles = self.angle_min_rad + self.angle_increment_rad * np.arange(self.samples)
        object.__setattr__(self, "angles_rad", angles)

    @property
    def angle_increment_rad(self) -> float:
        """Angle between beams in rad: (max - min) / (samples - 1), as Gazebo computes it."""
        if self.samples == 1:
            return 0.0
        return (self.angle_max_rad - self.angle_min_rad) / (self.samples - 1)

    def true_ranges(
        self, world: World, pose_xyz_yaw_of_scanner: tuple[float, float, float, float]
    ) -> np.ndarray:
        """Exact distances (samples,) float64 in m from the scanner pose (map x, y, z, yaw rad).

        ``inf`` where nothing is hit within ``range_max_m``; no noise, no masking.
        """
        x, y, z, yaw = (float(v) for v in pose_xyz_yaw_of_scanner)
        return world.raycast_2d(np.array([x, y]), yaw + self.angles_rad, z, self.range_max_m)

    def scan(
        self,
        world: World,
        pose_xyz_yaw_of_scanner: tuple[float, float, float, float],
        rng: np.random.Generator | None,
    ) -> np.ndarray:
        """One scan: ranges (samples,) float32 in m, as a LaserScan's ``ranges``.

        Args:
            world: the world to scan.
            pose_xyz_yaw_of_scanner: scanner (base_scan) pose in the map frame:
                x, y, z in m and yaw in rad.
            rng: noise source; ``None`` gives noise-free ranges. Each call draws
                exactly ``samples`` normals, whatever is hit.

        Returns:
            Ranges with ``+inf`` for no return within range_max and ``-inf`` for
            returns closer than range_min (see the module docstring).
        """
        true = self.true_ranges(world, pose_xyz_yaw_of_scanner)
        noisy = true.copy()
        if rng is not None and self.noise_sd_m > 0.0:
            noisy += rng.normal(0.0, self.noise_sd_m, size=self.samples)
        out = np.clip(noisy, self.range_min_m, self.range_max_m)
        out[true >= self.range_max_m] = np.inf
        out[true <= self.range_min_m] = -np.inf
        return out.astype(np.float32)
