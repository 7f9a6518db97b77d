"""Builders of the ROS 2 messages the simulator writes, serialized to CDR with a rosbags typestore.

Stamps are int nanoseconds; quaternions are x, y, z, w (ROS order); poses in metres/radians.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from rosbags.typesys.store import Typestore

from bagtools_simulate.writer.layout import FixedLayout

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
        self._Imu = t["sensor_msgs/msg/Imu"]
        self._JointState = t["sensor_msgs/msg/JointState"]
        self._CameraInfo = t["sensor_msgs/msg/CameraInfo"]
        self._RegionOfInterest = t["sensor_msgs/msg/RegionOfInterest"]
        self._layouts: dict[tuple, FixedLayout] = {}
        self._pose_cov = np.diag(ODOM_POSE_COV_DIAG).ravel()
        self._twist_cov = np.diag(ODOM_TWIST_COV_DIAG).ravel()
        self._truth_cov = np.diag(TRUTH_COV_DIAG).ravel()
        self._xyz_fields = [self._PointField(name=n, offset=4 * i, datatype=7, count=1) for i, n in enumerate("xyz")]

    def _serialize(self, msg: Any) -> bytes:
        return bytes(self.ts.serialize_cdr(msg, msg.__msgtype__))

    def _header_sec_ns(self, sec: float, nanosec: float, frame_id: str) -> Any:
        return self._Header(stamp=self._Time(sec=int(sec), nanosec=int(nanosec)), frame_id=frame_id)

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

    def camera_info(self, stamp_ns: int, frame: str, width: int, height: int, K: np.ndarray, P: np.ndarray) -> bytes:
        """sensor_msgs/CameraInfo of an undistorted pinhole (plumb_bob, zero distortion) with intrinsics K (3x3), P (3x4)."""
        msg = self._CameraInfo(
            header=self.header(stamp_ns, frame),
            height=int(height),
            width=int(width),
            distortion_model="plumb_bob",
            d=np.zeros(5),
            k=np.asarray(K, dtype=np.float64).ravel(),
            r=np.eye(3).ravel(),
            p=np.asarray(P, dtype=np.float64).ravel(),
            binning_x=0,
            binning_y=0,
            roi=self._RegionOfInterest(x_offset=0, y_offset=0, height=0, width=0, do_rectify=False),
        )
        return self._serialize(msg)

    # Batches: N messages of one fixed layout at once (see bagtools_simulate.writer.layout).

    def _layout(self, key: tuple, build: Any, fields: dict[str, str]) -> FixedLayout:
        if key not in self._layouts:
            self._layouts[key] = FixedLayout.probe(lambda v: self._serialize(build(v)), fields)
        return self._layouts[key]

    def planar_tf_batch(self, stamps_ns: np.ndarray, parent: str, child: str, poses: np.ndarray) -> np.ndarray:
        """(N, size) TFMessages, each with one planar T_parent_child at ``poses`` (N, 3) [x, y, yaw] (m, rad)."""
        def build(v: Mapping[str, float]) -> Any:
            return self._TFMessage(transforms=[self._TransformStamped(
                header=self._header_sec_ns(v["sec"], v["nanosec"], parent), child_frame_id=child,
                transform=self._Transform(translation=self._Vector3(x=v["x"], y=v["y"], z=0.0),
                                          rotation=self._Quaternion(x=0.0, y=0.0, z=v["qz"], w=v["qw"])))])

        layout = self._layout(("planar_tf", parent, child), build,
                              {"sec": "i4", "nanosec": "u4", "x": "f8", "y": "f8", "qz": "f8", "qw": "f8"})
        sec, nanosec = np.divmod(np.asarray(stamps_ns, dtype=np.int64), 1_000_000_000)
        yaw = poses[:, 2]
        return layout.pack(len(sec), {"sec": sec, "nanosec": nanosec, "x": poses[:, 0], "y": poses[:, 1],
                                      "qz": np.sin(0.5 * yaw), "qw": np.cos(0.5 * yaw)})

    def odometry_batch(self, stamps_ns: np.ndarray, frame: str, child: str, poses: np.ndarray, v_mps: np.ndarray,
                       w_radps: np.ndarray, truth: bool = False) -> np.ndarray:
        """(N, size) nav_msgs/Odometry: planar poses (N, 3) of ``child`` in ``frame``, twists (v, w) in ``child``."""
        pose_cov = self._truth_cov if truth else self._pose_cov
        twist_cov = self._truth_cov if truth else self._twist_cov

        def build(v: Mapping[str, float]) -> Any:
            pose = self._Pose(position=self._Point(x=v["x"], y=v["y"], z=0.0),
                              orientation=self._Quaternion(x=0.0, y=0.0, z=v["qz"], w=v["qw"]))
            twist = self._Twist(linear=self._Vector3(x=v["v"], y=0.0, z=0.0),
                                angular=self._Vector3(x=0.0, y=0.0, z=v["w"]))
            return self._Odometry(
                header=self._header_sec_ns(v["sec"], v["nanosec"], frame), child_frame_id=child,
                pose=self._PoseWithCovariance(pose=pose, covariance=pose_cov),
                twist=self._TwistWithCovariance(twist=twist, covariance=twist_cov))

        layout = self._layout(("odometry", frame, child, truth), build,
                              {"sec": "i4", "nanosec": "u4", "x": "f8", "y": "f8", "qz": "f8", "qw": "f8",
                               "v": "f8", "w": "f8"})
        sec, nanosec = np.divmod(np.asarray(stamps_ns, dtype=np.int64), 1_000_000_000)
        yaw = poses[:, 2]
        return layout.pack(len(sec), {"sec": sec, "nanosec": nanosec, "x": poses[:, 0], "y": poses[:, 1],
                                      "qz": np.sin(0.5 * yaw), "qw": np.cos(0.5 * yaw), "v": v_mps, "w": w_radps})

    def imu_batch(self, stamps_ns: np.ndarray, frame: str, quat_xyzw: np.ndarray, angular_velocity: np.ndarray,
                  linear_acceleration: np.ndarray, covariances: tuple[np.ndarray, np.ndarray, np.ndarray]) -> np.ndarray:
        """(N, size) sensor_msgs/Imu in ``frame``: quaternions (N, 4) x, y, z, w, rad/s (N, 3), m/s^2 (N, 3);
        the three row-major covariances (orientation, angular velocity, linear acceleration) are the same for all."""
        cov_q, cov_w, cov_a = (np.asarray(c, dtype=np.float64) for c in covariances)

        def build(v: Mapping[str, float]) -> Any:
            return self._Imu(
                header=self._header_sec_ns(v["sec"], v["nanosec"], frame),
                orientation=self._Quaternion(x=v["qx"], y=v["qy"], z=v["qz"], w=v["qw"]), orientation_covariance=cov_q,
                angular_velocity=self._Vector3(x=v["wx"], y=v["wy"], z=v["wz"]), angular_velocity_covariance=cov_w,
                linear_acceleration=self._Vector3(x=v["ax"], y=v["ay"], z=v["az"]),
                linear_acceleration_covariance=cov_a)

        names = ("qx", "qy", "qz", "qw", "wx", "wy", "wz", "ax", "ay", "az")
        layout = self._layout(("imu", frame, cov_q.tobytes(), cov_w.tobytes(), cov_a.tobytes()), build,
                              {"sec": "i4", "nanosec": "u4"} | {n: "f8" for n in names})
        sec, nanosec = np.divmod(np.asarray(stamps_ns, dtype=np.int64), 1_000_000_000)
        cols = np.hstack([quat_xyzw, angular_velocity, linear_acceleration])
        return layout.pack(len(sec), {"sec": sec, "nanosec": nanosec} | {n: cols[:, i] for i, n in enumerate(names)})

    def joint_state_batch(self, stamps_ns: np.ndarray, names: tuple[str, ...], positions_rad: np.ndarray,
                          velocities_radps: np.ndarray) -> np.ndarray:
        """(N, size) sensor_msgs/JointState (empty frame_id, no effort): positions and velocities (N, J) of ``names``."""
        n_joints = len(names)

        def build(v: Mapping[str, float]) -> Any:
            return self._JointState(
                header=self._header_sec_ns(v["sec"], v["nanosec"], ""), name=list(names),
                position=np.array([v[f"p{i}"] for i in range(n_joints)], dtype=np.float64),
                velocity=np.array([v[f"v{i}"] for i in range(n_joints)], dtype=np.float64),
                effort=np.zeros(0, dtype=np.float64))

        fields = {"sec": "i4", "nanosec": "u4"} | {f"p{i}": "f8" for i in range(n_joints)}
        fields |= {f"v{i}": "f8" for i in range(n_joints)}
        layout = self._layout(("joint_state", names), build, fields)
        sec, nanosec = np.divmod(np.asarray(stamps_ns, dtype=np.int64), 1_000_000_000)
        values: dict[str, np.ndarray] = {"sec": sec, "nanosec": nanosec}
        for i in range(n_joints):
            values[f"p{i}"] = positions_rad[:, i]
            values[f"v{i}"] = velocities_radps[:, i]
        return layout.pack(len(sec), values)

    def transforms_batch(self, stamps_ns: np.ndarray, edges: tuple[tuple[str, str], ...], xyz_m: np.ndarray,
                         quat_xyzw: np.ndarray) -> np.ndarray:
        """(N, size) TFMessages of E transforms each, all stamped ``stamps_ns`` (N,): ``edges`` (parent, child),
        translations (N, E, 3) m and rotations (N, E, 4) x, y, z, w."""
        def build(v: Mapping[str, float]) -> Any:
            return self._TFMessage(transforms=[
                self._TransformStamped(
                    header=self._header_sec_ns(v[f"sec{e}"], v[f"nanosec{e}"], parent), child_frame_id=child,
                    transform=self._Transform(
                        translation=self._Vector3(x=v[f"tx{e}"], y=v[f"ty{e}"], z=v[f"tz{e}"]),
                        rotation=self._Quaternion(x=v[f"qx{e}"], y=v[f"qy{e}"], z=v[f"qz{e}"], w=v[f"qw{e}"])))
                for e, (parent, child) in enumerate(edges)])

        fields: dict[str, str] = {}
        for e in range(len(edges)):
            fields |= {f"sec{e}": "i4", f"nanosec{e}": "u4"}
            fields |= {f"{c}{e}": "f8" for c in ("tx", "ty", "tz", "qx", "qy", "qz", "qw")}
        layout = self._layout(("transforms", edges), build, fields)
        sec, nanosec = np.divmod(np.asarray(stamps_ns, dtype=np.int64), 1_000_000_000)
        values: dict[str, np.ndarray] = {}
        for e in range(len(edges)):
            values |= {f"sec{e}": sec, f"nanosec{e}": nanosec}
            values |= {f"{c}{e}": xyz_m[:, e, i] for i, c in enumerate(("tx", "ty", "tz"))}
            values |= {f"{c}{e}": quat_xyzw[:, e, i] for i, c in enumerate(("qx", "qy", "qz", "qw"))}
        return layout.pack(len(sec), values)
