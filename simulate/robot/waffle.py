"""TurtleBot3 Waffle constants, its joints (from ROBOTIS' ``turtlebot3_waffle.urdf``) and its URDF text.

Lengths in metres, angles in radians, speeds in m/s and rad/s. The joint origins are the
numbers of ROBOTIS' URDF (``turtlebot3_description/urdf/turtlebot3_waffle.urdf``), which
robot_state_publisher turns into ``/tf_static`` (fixed joints) and ``/tf`` (the two
continuous wheel joints, from ``/joint_states``); rotations are URDF ``rpy`` as written
there (e.g. -1.57, not -pi/2), so the frames are the ones a real Waffle publishes.
"""

from __future__ import annotations

from dataclasses import dataclass
from html import escape

import numpy as np

from bagtools.transforms import axang2quat, quat2xyzw, quatconj, quatmultiply

WHEEL_SEPARATION_M = 0.287
WHEEL_RADIUS_M = 0.033
MAX_LINEAR_MPS = 0.26
MAX_ANGULAR_RADPS = 1.82
# nav2_bringup's nav2_params.yaml uses robot_radius 0.22 for the TurtleBot3 costmaps.
ROBOT_RADIUS_M = 0.22
ENCODER_TICKS_PER_REV = 4096  # Dynamixel XM430 position resolution
ROBOT_NAME = "turtlebot3_waffle"
WHEEL_JOINTS = ("wheel_left_joint", "wheel_right_joint")


@dataclass(frozen=True)
class Joint:
    """A URDF joint: ``parent`` -> ``child`` at ``xyz_m``/``rpy_rad`` (URDF origin), about ``axis`` if it moves."""

    name: str
    kind: str  # "fixed" or "continuous"
    parent: str
    child: str
    xyz_m: tuple[float, float, float]
    rpy_rad: tuple[float, float, float] = (0.0, 0.0, 0.0)
    axis: tuple[float, float, float] = (0.0, 0.0, 1.0)

    @property
    def quat_wxyz(self) -> np.ndarray:
        """The origin's rotation as a quaternion [w x y z] (URDF rpy: fixed axes, roll about x first)."""
        return _rpy_quat(self.rpy_rad)

    @property
    def quat_xyzw(self) -> tuple[float, float, float, float]:
        """The origin's rotation as a quaternion x, y, z, w (URDF rpy: fixed axes, roll about x first)."""
        x, y, z, w = quat2xyzw(self.quat_wxyz)
        return (float(x), float(y), float(z), float(w))

    def matrix(self, angle_rad: float = 0.0) -> np.ndarray:
        """The 4x4 T_parent_child at joint position ``angle_rad`` (0 for fixed joints)."""
        quat = self.quat_wxyz
        if self.kind != "fixed" and angle_rad != 0.0:
            quat = quatmultiply(quat, axang2quat([*self.axis, angle_rad]))
        T = np.eye(4)
        T[:3, :3] = _quat_matrix(quat)
        T[:3, 3] = self.xyz_m
        return T


def _rpy_quat(rpy_rad: tuple[float, float, float]) -> np.ndarray:
    """URDF rpy (roll about fixed x, then pitch about fixed y, then yaw about fixed z) -> quaternion [w x y z].

    The Hamilton product q_z(yaw) q_y(pitch) q_x(roll), in scipy's ``from_euler("xyz", rpy)`` order.
    """
    roll, pitch, yaw = rpy_rad
    return quatmultiply(axang2quat([0.0, 0.0, 1.0, yaw]),
                        quatmultiply(axang2quat([0.0, 1.0, 0.0, pitch]), axang2quat([1.0, 0.0, 0.0, roll])))


def _quat_matrix(quat_wxyz: np.ndarray) -> np.ndarray:
    """Rotation matrix (3, 3) of a unit quaternion [w x y z]: its columns are the axes rotated, q e_i q*."""
    axes = np.hstack([np.zeros((3, 1)), np.eye(3)])  # e_x, e_y, e_z as pure quaternions
    return quatmultiply(quatmultiply(quat_wxyz, axes), quatconj(quat_wxyz))[:, 1:].T


_OPTICAL_RPY = (-1.57, 0.0, -1.57)  # as in the URDF: z forward, x right, y down
JOINTS: tuple[Joint, ...] = (
    Joint("base_joint", "fixed", "base_footprint", "base_link", (0.0, 0.0, 0.010)),
    Joint("wheel_left_joint", "continuous", "base_link", "wheel_left_link", (0.0, 0.144, 0.023), (-1.57, 0.0, 0.0)),
    Joint("wheel_right_joint", "continuous", "base_link", "wheel_right_link", (0.0, -0.144, 0.023), (-1.57, 0.0, 0.0)),
    Joint("caster_back_right_joint", "fixed", "base_link", "caster_back_right_link", (-0.177, -0.064, -0.004),
          (-1.57, 0.0, 0.0)),
    Joint("caster_back_left_joint", "fixed", "base_link", "caster_back_left_link", (-0.177, 0.064, -0.004),
          (-1.57, 0.0, 0.0)),
    Joint("imu_joint", "fixed", "base_link", "imu_link", (0.0, 0.0, 0.068)),
    # 0.122 as in the URDF that robot_state_publisher publishes (the Gazebo SDF says 0.121).
    Joint("scan_joint", "fixed", "base_link", "base_scan", (-0.064, 0.0, 0.122)),
    Joint("camera_joint", "fixed", "base_link", "camera_link", (0.064, -0.065, 0.094)),
    Joint("camera_rgb_joint", "fixed", "camera_link", "camera_rgb_frame", (0.005, 0.018, 0.013)),
    Joint("camera_rgb_optical_joint", "fixed", "camera_rgb_frame", "camera_rgb_optical_frame", (0.0, 0.0, 0.0),
          _OPTICAL_RPY),
    Joint("camera_depth_joint", "fixed", "camera_link", "camera_depth_frame", (0.005, 0.028, 0.013)),
    Joint("camera_depth_optical_joint", "fixed", "camera_depth_frame", "camera_depth_optical_frame", (0.0, 0.0, 0.0),
          _OPTICAL_RPY),
)
STATIC_TRANSFORMS: tuple[Joint, ...] = tuple(j for j in JOINTS if j.kind == "fixed")
WHEEL_JOINT_MODELS: tuple[Joint, ...] = tuple(j for j in JOINTS if j.name in WHEEL_JOINTS)


def T_base_footprint_frame(frame: str, wheel_angles_rad: dict[str, float] | None = None) -> np.ndarray:
    """The 4x4 T_base_footprint_<frame>, chaining joints down from base_footprint (wheels at the given angles)."""
    by_child = {j.child: j for j in JOINTS}
    angles = wheel_angles_rad or {}
    T = np.eye(4)
    while frame != "base_footprint":
        if frame not in by_child:
            raise ValueError(f"unknown frame {frame!r}")
        joint = by_child[frame]
        T = joint.matrix(angles.get(joint.name, 0.0)) @ T
        frame = joint.parent
    return T


def wheel_quats_xyzw(joint: Joint, angles_rad: np.ndarray) -> np.ndarray:
    """Rotations (N, 4) x, y, z, w of T_base_link_wheel at wheel angles (N,) rad, as robot_state_publisher computes them."""
    angles = np.asarray(angles_rad, dtype=float).reshape(-1)
    turns = axang2quat(np.column_stack([np.broadcast_to(joint.axis, (len(angles), 3)), angles]))
    return quat2xyzw(quatmultiply(joint.quat_wxyz, turns))


def _quoteattr(value: str) -> str:
    """``value`` as a double-quoted XML attribute value (html.escape: xml.sax.saxutils would import urllib, ~10 ms)."""
    return f'"{escape(value, quote=True)}"'


def urdf_text() -> str:
    """A URDF of the Waffle's links and joints (no meshes), consistent with the transforms the simulator publishes.

    Wheels carry their cylinder collision (radius ``WHEEL_RADIUS_M``); this is what ``/robot_description`` holds.
    """
    def fmt(values: tuple[float, ...]) -> str:
        return " ".join(f"{v:g}" for v in values)

    links = ["base_footprint"] + [j.child for j in JOINTS]
    lines = ['<?xml version="1.0" ?>', f"<robot name={_quoteattr(ROBOT_NAME)}>"]
    for link in links:
        if link in ("wheel_left_link", "wheel_right_link"):
            lines += [f"  <link name={_quoteattr(link)}>", "    <collision>", '      <origin xyz="0 0 0" rpy="0 0 0"/>',
                      f'      <geometry><cylinder length="0.018" radius="{WHEEL_RADIUS_M:g}"/></geometry>',
                      "    </collision>", "  </link>"]
        else:
            lines.append(f"  <link name={_quoteattr(link)}/>")
    for j in JOINTS:
        lines += [f"  <joint name={_quoteattr(j.name)} type={_quoteattr(j.kind)}>",
                  f"    <parent link={_quoteattr(j.parent)}/>",
                  f"    <child link={_quoteattr(j.child)}/>",
                  f'    <origin xyz="{fmt(j.xyz_m)}" rpy="{fmt(j.rpy_rad)}"/>']
        if j.kind != "fixed":
            lines.append(f'    <axis xyz="{fmt(j.axis)}"/>')
        lines.append("  </joint>")
    lines.append("</robot>")
    return "\n".join(lines) + "\n"
