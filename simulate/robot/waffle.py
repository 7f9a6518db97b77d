"""TurtleBot3 Waffle constants and its static transforms (from the Waffle URDF).

Lengths in metres, angles in radians, speeds in m/s and rad/s.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

WHEEL_SEPARATION_M = 0.287
WHEEL_RADIUS_M = 0.033
MAX_LINEAR_MPS = 0.26
MAX_ANGULAR_RADPS = 1.82
# nav2_bringup's nav2_params.yaml uses robot_radius 0.22 for the TurtleBot3 costmaps.
ROBOT_RADIUS_M = 0.22
ENCODER_TICKS_PER_REV = 4096  # Dynamixel XM430 position resolution


@dataclass(frozen=True)
class StaticTransform:
    """A fixed transform T_parent_child: translation in metres, rotation as quaternion x, y, z, w (ROS order)."""

    parent: str
    child: str
    xyz_m: tuple[float, float, float]
    quat_xyzw: tuple[float, float, float, float]

    def matrix(self) -> np.ndarray:
        """The 4x4 homogeneous T_parent_child."""
        T = np.eye(4)
        T[:3, :3] = Rotation.from_quat(self.quat_xyzw).as_matrix()
        T[:3, 3] = self.xyz_m
        return T


def _quat_xyzw_from_rpy(roll: float, pitch: float, yaw: float) -> tuple[float, float, float, float]:
    x, y, z, w = Rotation.from_euler("xyz", [roll, pitch, yaw]).as_quat()
    return (float(x), float(y), float(z), float(w))


_IDENTITY = (0.0, 0.0, 0.0, 1.0)
STATIC_TRANSFORMS: tuple[StaticTransform, ...] = (
    StaticTransform("base_footprint", "base_link", (0.0, 0.0, 0.010), _IDENTITY),
    StaticTransform("base_link", "base_scan", (-0.064, 0.0, 0.121), _IDENTITY),
    StaticTransform("base_link", "camera_link", (0.064, -0.065, 0.094), _IDENTITY),
    StaticTransform("camera_link", "camera_rgb_frame", (0.005, 0.018, 0.013), _IDENTITY),
    StaticTransform(
        "camera_rgb_frame", "camera_rgb_optical_frame", (0.0, 0.0, 0.0), _quat_xyzw_from_rpy(-np.pi / 2, 0.0, -np.pi / 2)
    ),
)


def T_base_footprint_frame(frame: str) -> np.ndarray:
    """The 4x4 T_base_footprint_<frame> by chaining the static transforms down from base_footprint."""
    by_child = {st.child: st for st in STATIC_TRANSFORMS}
    T = np.eye(4)
    while frame != "base_footprint":
        if frame not in by_child:
            raise ValueError(f"unknown frame {frame!r}")
        st = by_child[frame]
        T = st.matrix() @ T
        frame = st.parent
    return T
