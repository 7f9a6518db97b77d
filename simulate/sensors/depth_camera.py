"""Depth camera model producing organized point clouds, as Gazebo's depth plugins do.

Defaults follow the TurtleBot3 Waffle's simulated Intel RealSense R200: the
horizontal field of view 1.02974 rad is the ``intel_realsense_r200`` camera in
ROBOTIS' ``turtlebot3_waffle/model.sdf``; the valid depth band 0.4-5.0 m is
the ``pointCloudCutoff`` set in ``turtlebot3_waffle.gazebo.xacro`` and the
depth plugin's default ``pointCloudCutoffMax``. Image size is the caller's
choice (the model renders 1920x1080; 160x120 keeps bags small).

The cloud is published in ``camera_rgb_optical_frame``, as the Waffle's Gazebo depth
plugin publishes it (or, asked for, ``camera_depth_optical_frame``, the R200's depth
optical frame in ROBOTIS' URDF), seen from that frame, with its intrinsics on
``/camera/depth/camera_info`` (``K``, ``P``).

Geometry is Gazebo's: a pinhole with square pixels, focal length
``f = width / (2 tan(hfov / 2))`` pixels and principal point at the image
centre ``((width - 1) / 2, (height - 1) / 2)``. Each pixel's point is
``(depth (u - cx) / f, depth (v - cy) / f, depth)`` in the optical frame
(z forward, x right, y down), where depth is the z coordinate; pixels whose
depth is not strictly inside (near, far), or that see nothing, are NaN.

Noise (our choice; Gazebo's model adds none): stereo depth error grows with
the square of depth, so each depth gets Gaussian noise with sd
``noise_sd_at_1m_m * depth**2`` (2.5 mm at 1 m, 1 cm at 2 m by default),
applied along the pixel's ray.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from bagtools_simulate.world import World


@dataclass(frozen=True)
class DepthCamera:
    """A pinhole depth camera; ``points`` ray-casts the world into an (H, W, 3) cloud."""

    width: int = 160
    height: int = 120
    hfov_rad: float = 1.02974
    near_m: float = 0.4
    far_m: float = 5.0
    noise_sd_at_1m_m: float = 0.0025
    _rays_optical: np.ndarray = field(init=False, repr=False, compare=False)
    _ray_norms: np.ndarray = field(init=False, repr=False, compare=False)
    _unit_rays_optical: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if self.width < 1 or self.height < 1:
            raise ValueError(f"image size must be positive, got {self.width}x{self.height}")
        if not 0.0 < self.hfov_rad < np.pi:
            raise ValueError(f"hfov_rad must be in (0, pi), got {self.hfov_rad}")
        if not 0.0 <= self.near_m < self.far_m:
            raise ValueError("need 0 <= near_m < far_m")
        if self.noise_sd_at_1m_m < 0.0:
            raise ValueError("noise_sd_at_1m_m must be >= 0")
        u = (np.arange(self.width) - self.cx) / self.focal_px
        v = (np.arange(self.height) - self.cy) / self.focal_px
        rays = np.empty((self.height, self.width, 3))
        rays[:, :, 0] = u[None, :]
        rays[:, :, 1] = v[:, None]
        rays[:, :, 2] = 1.0
        norms = np.sqrt(rays[:, :, 0] ** 2 + rays[:, :, 1] ** 2 + 1.0)
        units = (rays / norms[:, :, None]).reshape(-1, 3)
        for a in (rays, norms, units):
            a.flags.writeable = False
        object.__setattr__(self, "_rays_optical", rays)
        object.__setattr__(self, "_ray_norms", norms.reshape(-1))
        object.__setattr__(self, "_unit_rays_optical", units)

    @property
    def focal_px(self) -> float:
        """Focal length in pixels (same for x and y)."""
        return self.width / (2.0 * np.tan(self.hfov_rad / 2.0))

    @property
    def K(self) -> np.ndarray:
        """The 3x3 intrinsic matrix in pixels (CameraInfo ``k``): [[f, 0, cx], [0, f, cy], [0, 0, 1]]."""
        return np.array([[self.focal_px, 0.0, self.cx], [0.0, self.focal_px, self.cy], [0.0, 0.0, 1.0]])

    @property
    def P(self) -> np.ndarray:
        """The 3x4 projection matrix in pixels (CameraInfo ``p``): K with a zero fourth column (no stereo baseline)."""
        return np.hstack([self.K, np.zeros((3, 1))])

    @property
    def cx(self) -> float:
        """Principal point column in pixels."""
        return 0.5 * (self.width - 1)

    @property
    def cy(self) -> float:
        """Principal point row in pixels."""
        return 0.5 * (self.height - 1)

    def depth(
        self, world: World, T_map_optical: np.ndarray, rng: np.random.Generator | None
    ) -> np.ndarray:
        """Depth image (H, W) float64 in m (optical z), NaN where invalid.

        Args:
            world: the world to look at.
            T_map_optical: (4, 4) pose of the optical frame (the cloud's frame) in the map.
            rng: noise source; ``None`` gives exact depths. Each call draws
                exactly H*W normals when noise is on.
        """
        T = np.asarray(T_map_optical, dtype=float)
        if T.shape != (4, 4):
            raise ValueError(f"T_map_optical must be 4x4, got {T.shape}")
        norms = self._ray_norms
        dirs_map = self._unit_rays_optical @ T[:3, :3].T
        max_range = self.far_m * float(norms.max())
        dist = world.raycast_3d(T[:3, 3], dirs_map, max_range)
        z = dist / norms  # inf stays inf
        if rng is not None and self.noise_sd_at_1m_m > 0.0:
            noise = rng.standard_normal(size=z.shape)
            with np.errstate(invalid="ignore"):  # inf + -inf for misses: NaN, masked below
                z += noise * self.noise_sd_at_1m_m * (z * z)
        with np.errstate(invalid="ignore"):
            z[~((z > self.near_m) & (z < self.far_m))] = np.nan
        return z.reshape(self.height, self.width)

    def points(
        self, world: World, T_map_optical: np.ndarray, rng: np.random.Generator | None
    ) -> np.ndarray:
        """Organized cloud (H, W, 3) float32 in m in the optical frame, NaN where invalid.

        Args:
            world: the world to look at.
            T_map_optical: (4, 4) pose of the optical frame (the cloud's frame)
                in the map (maps optical-frame points into the map).
            rng: noise source; ``None`` gives exact points.
        """
        z = self.depth(world, T_map_optical, rng)
        return (self._rays_optical * z[:, :, None]).astype(np.float32)
