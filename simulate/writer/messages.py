"""Builders of the ROS 2 messages the simulator writes, serialized to CDR with a rosbags typestore.

Stamps are int nanoseconds; quaternions are x, y, z, w (ROS order); poses in metres/radians.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from rosbags.typesys.store import Typestore

# Pose/twist covariance diagonals (x, y, z, roll, pitch, yaw): planar odometry leaves z,
# roll and pitch unobserved, as turtlebot3_node and Gazebo's diff drive plugin do.
ODOM_POSE_COV_DIAG = (1e-3, 1e-3, 1e6, 1e6, 1e6, 1e-2)
ODOM_TWIST_COV_DIAG = (1e-4, 1e-4, 1e6, 1e6, 1e6, 1e-3)
TRUTH_COV_DIAG = (1e-9, 1e-9, 1e-9, 1e-9, 1e-9, 1e-9)


class MessageBuilder:
    """Serializes simulator messages with one typestore (Humble or Jazzy definitions)."""

    def __init__(self, typestore: Typestore) -> None:
        self.ts = typestore
        t = typestore.types
        self._Time = t["builtin_interfaces/msg/Time"]
        self._Header = t["std_msgs/msg/Header"]
        self._TransformStamped = t["geometry_msgs/msg/TransformStamped"]
        self._Transform = t["geometry_msgs/msg/Transform"]
        self._Vector3 = t["geometry_msgs/msg/Vector3"]
        self._Quaternion = t["geometry_msgs/msg/Quaternion"]
        self._Point = t["geometry_msgs/msg/Point"]
        self._Pose = t["geometry_msgs/msg/Pose"]
        self._PoseWithCovariance = t["geometry_msgs/msg/PoseWithCovariance"]
        self._Twist = t["geometry_msgs/msg/Twist"]
        self._TwistWithCovariance = t["geometry_msgs/msg/TwistWithCovariance"]
        self._TFMessage = t["tf2_msgs/msg/TFMessage"]
        self._Odometry = t["nav_msgs/msg/Odometry"]
        self._LaserScan = t["sensor_msgs/msg/LaserScan"]
        self._PointCloud2 = t["sensor_msgs/msg/PointCloud2"]
        self._PointField = t["sensor_msgs/msg/PointField"]
        self._PointStamped = t["geometry_msgs/msg/PointStamped"]
        self._String = t["std_msgs/msg/String"]
        self._pose_cov = np.diag(ODOM_POSE_COV_DIAG).ravel()
        self._twist_cov = np.diag(ODOM_TWIST_COV_DIAG).ravel()
        self._truth_cov = np.diag(TRUTH_COV_DIAG).ravel()
        self._xyz_fields = [self._PointField(name=n, offset=4 * i, datatype=7, count=1) for i, n in enumerate("xyz")]

    def _serialize(self, msg: Any) -> bytes:
        return bytes(self.ts.serialize_cdr(msg, msg.__msgtype__))

    def header(self, stamp_ns: int, frame_id: str) -> Any:
        """A std_msgs/Header with stamp ``stamp_ns`` (ns since epoch)."""
        sec, nanosec = divmod(int(stamp_ns), 1_000_000_000)
        return self._Header(stamp=self._Time(sec=sec, nanosec=nanosec), frame_id=frame_id)

    def _transform(self, stamp_ns: int, parent: str, child: str, xyz: Any, quat_xyzw: Any) -> Any:
        return self._TransformStamped(
            header=self.header(stamp_ns, parent),
            child_frame_id=child,
            transform=self._Transform(
                translation=self._Vector3(x=float(xyz[0]), y=float(xyz[1]), z=float(xyz[2])),
                rotation=self._Quaternion(
                    x=float(quat_xyzw[0]), y=float(quat_xyzw[1]), z=float(quat_xyzw[2]), w=float(quat_xyzw[3])
                ),
            ),
        )

    def tf_message(self, transforms: list[tuple[int, str, str, Any, Any]]) -> bytes:
        """tf2_msgs/TFMessage from (stamp_ns, parent, child, xyz_m, quat_xyzw) tuples."""
        return self._serialize(self._TFMessage(transforms=[self._transform(*t) for t in transforms]))

    def planar_tf(self, stamp_ns: int, parent: str, child: str, x: float, y: float, yaw: float) -> bytes:
        """A TFMessage with one planar transform T_parent_child (x, y in m, yaw in rad, z = 0)."""
        quat = (0.0, 0.0, np.sin(0.5 * yaw), np.cos(0.5 * yaw))
        return self.tf_message([(stamp_ns, parent, child, (x, y, 0.0), quat)])

    def odometry(
        self, stamp_ns: int, frame: str, child: str, x: float, y: float, yaw: float, v_mps: float, w_radps: float, truth: bool = False
    ) -> bytes:
        """nav_msgs/Odometry: planar pose of ``child`` in ``frame``, twist (v, w) in ``child``."""
        pose = self._Pose(
            position=self._Point(x=float(x), y=float(y), z=0.0),
            orientation=self._Quaternion(x=0.0, y=0.0, z=float(np.sin(0.5 * yaw)), w=float(np.cos(0.5 * yaw))),
        )
        twist = self._Twist(linear=self._Vector3(x=float(v_mps), y=0.0, z=0.0), angular=self._Vector3(x=0.0, y=0.0, z=float(w_radps)))
        msg = self._Odometry(
            header=self.header(stamp_ns, frame),
            child_frame_id=child,
            pose=self._PoseWithCovariance(pose=pose, covariance=self._truth_cov if truth else self._pose_cov),
            twist=self._TwistWithCovariance(twist=twist, covariance=self._truth_cov if truth else self._twist_cov),
        )
        return self._serialize(msg)

    def laser_scan(
        self,
        stamp_ns: int,
        frame: str,
        ranges_m: np.ndarray,
        angle_min_rad: float,
        angle_increment_rad: float,
        range_min_m: float,
        range_max_m: float,
        scan_time_s: float,
    ) -> bytes:
        """sensor_msgs/LaserScan; ``ranges_m`` float32 with +inf for no return; no intensities."""
        ranges = np.asarray(ranges_m, dtype=np.float32)
        msg = self._LaserScan(
            header=self.header(stamp_ns, frame),
            angle_min=float(angle_min_rad),
            angle_max=float(angle_min_rad + angle_increment_rad * (len(ranges) - 1)),
            angle_increment=float(angle_increment_rad),
            time_increment=0.0,  # every beam is ray-cast at the stamp, as Gazebo's ray sensor does
            scan_time=float(scan_time_s),
            range_min=float(range_min_m),
            range_max=float(range_max_m),
            ranges=ranges,
            intensities=np.zeros(0, dtype=np.float32),
        )
        return self._serialize(msg)

    def point_cloud(self, stamp_ns: int, frame: str, points_xyz: np.ndarray) -> bytes:
        """sensor_msgs/PointCloud2, organized (H, W), fields x, y, z float32 little endian, NaN = invalid."""
        pts = np.ascontiguousarray(points_xyz, dtype="<f4")
        if pts.ndim != 3 or pts.shape[2] != 3:
            raise ValueError(f"points must be (H, W, 3), got {pts.shape}")
        h, w = pts.shape[:2]
        msg = self._PointCloud2(
            header=self.header(stamp_ns, frame),
            height=h,
            width=w,
            fields=self._xyz_fields,
            is_bigendian=False,
            point_step=12,
            row_step=12 * w,
            data=pts.reshape(-1).view(np.uint8),
            is_dense=bool(np.isfinite(pts).all()),
        )
        return self._serialize(msg)

    def point_stamped(self, stamp_ns: int, frame: str, xyz_m: Any) -> bytes:
        """geometry_msgs/PointStamped at ``xyz_m`` in ``frame``."""
        point = self._Point(x=float(xyz_m[0]), y=float(xyz_m[1]), z=float(xyz_m[2]))
        return self._serialize(self._PointStamped(header=self.header(stamp_ns, frame), point=point))

    def string(self, text: str) -> bytes:
        """std_msgs/String."""
        return self._serialize(self._String(data=text))
