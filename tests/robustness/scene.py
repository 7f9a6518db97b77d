"""A small synthetic robot recording whose messages can be damaged one field at a time.

A robot drives for a few seconds through a walled room with one box in it. The
scene holds plain Python descriptions of every message (tf, scans, clouds,
odometry, ground truth) so a corpus case can change exactly one thing (an
``angle_increment``, a quaternion, a stamp) before the bag is written with
rosbags, as rosbag2 MCAP (zstd or uncompressed chunks), rosbag2 sqlite3 or a
ROS 1 bag.

Every command of bagtools works on the undamaged scene (exit 0, no warning):
map -> odom -> base_link -> {base_scan, camera_link}, /scan, /odom,
/ground_truth and /camera/depth/points.
"""

from __future__ import annotations

import copy
import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin, Writer
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

S = 1_000_000_000
T0 = 1_700_000_000 * S

ROS2 = get_typestore(Stores.ROS2_HUMBLE)

# The room: walls of [-3, 6] x [-3, 3] m and a box at [2, 2.6] x [1, 1.6].
_SEGMENTS = np.array([
    [-3, -3, 6, -3], [6, -3, 6, 3], [6, 3, -3, 3], [-3, 3, -3, -3],
    [2.0, 1.0, 2.6, 1.0], [2.6, 1.0, 2.6, 1.6], [2.6, 1.6, 2.0, 1.6], [2.0, 1.6, 2.0, 1.0],
], dtype=np.float64)

BASE_TO_SCAN = (-0.05, 0.0, 0.2)
BASE_TO_CAMERA = (0.1, 0.0, 0.3)
MAP_TO_ODOM = (0.05, -0.03, 0.02)  # x, y, yaw


def yaw_quat(yaw: float) -> tuple[float, float, float, float]:
    """x, y, z, w of a rotation by ``yaw`` about z."""
    return (0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2))


def robot_pose(t_s: float) -> tuple[float, float, float]:
    """x, y, yaw of base_link in map at ``t_s`` seconds into the scene."""
    x = -2.0 + 0.4 * t_s
    y = 0.3 * math.sin(0.5 * t_s)
    yaw = math.atan2(0.15 * math.cos(0.5 * t_s), 0.4)
    return x, y, yaw


def _compose(a: tuple[float, float, float], b: tuple[float, float, float]) -> tuple[float, float, float]:
    ax, ay, ath = a
    bx, by, bth = b
    return (ax + math.cos(ath) * bx - math.sin(ath) * by, ay + math.sin(ath) * bx + math.cos(ath) * by, ath + bth)


def _inverse(a: tuple[float, float, float]) -> tuple[float, float, float]:
    x, y, th = a
    return (-math.cos(th) * x - math.sin(th) * y, math.sin(th) * x - math.cos(th) * y, -th)


def raycast(origin_xy: tuple[float, float], angles: np.ndarray, max_range: float) -> np.ndarray:
    """Distances from ``origin_xy`` along world ``angles`` to the room's walls (inf beyond ``max_range``)."""
    ox, oy = origin_xy
    dx, dy = np.cos(angles)[:, None], np.sin(angles)[:, None]
    x1, y1, x2, y2 = (_SEGMENTS[:, i][None, :] for i in range(4))
    ex, ey = x2 - x1, y2 - y1
    denom = dx * ey - dy * ex
    with np.errstate(divide="ignore", invalid="ignore"):
        t = ((x1 - ox) * ey - (y1 - oy) * ex) / denom
        u = ((x1 - ox) * dy - (y1 - oy) * dx) / denom
    hit = (np.abs(denom) > 1e-12) & (t > 1e-9) & (u >= 0) & (u <= 1)
    dist = np.where(hit, t, np.inf).min(axis=1)
    return np.where(dist <= max_range, dist, np.inf)


def _wall_points() -> np.ndarray:
    """(N,3) points on the walls and the box, 0.2 m apart, at three heights."""
    pts = []
    for x1, y1, x2, y2 in _SEGMENTS:
        n = max(2, int(math.hypot(x2 - x1, y2 - y1) / 0.2))
        s = np.linspace(0, 1, n, endpoint=False)
        for z in (0.1, 0.5, 0.9):
            pts.append(np.column_stack((x1 + s * (x2 - x1), y1 + s * (y2 - y1), np.full(n, z))))
    return np.vstack(pts)


_WALLS = _wall_points()


@dataclass
class Tf:
    """One TransformStamped."""

    stamp_ns: int
    parent: str
    child: str
    xyz: tuple[float, float, float]
    quat_xyzw: tuple[float, float, float, float]


@dataclass
class Scan:
    stamp_ns: int
    frame_id: str
    angle_min: float
    angle_max: float
    angle_increment: float
    range_min: float
    range_max: float
    ranges: np.ndarray


@dataclass
class Odom:
    stamp_ns: int
    frame_id: str
    child: str
    xyz: tuple[float, float, float]
    quat_xyzw: tuple[float, float, float, float]
    linear: tuple[float, float, float] = (0.0, 0.0, 0.0)
    angular: tuple[float, float, float] = (0.0, 0.0, 0.0)


@dataclass
class Cloud:
    """A PointCloud2 of float32 x, y, z; ``overrides`` replaces message fields after it is built."""

    stamp_ns: int
    frame_id: str
    xyz: np.ndarray
    point_step: int = 16
    bigendian_data: bool = False
    overrides: dict[str, Any] = field(default_factory=dict)


@dataclass
class Entry:
    """One message to write: topic, bag (log) time and its description."""

    topic: str
    log_ns: int
    item: Any  # list[Tf] for /tf and /tf_static, Scan, Odom, Cloud, or a ready message (raw_type set)
    raw_type: str | None = None


@dataclass
class Scene:
    """The messages of a recording, as editable descriptions, in log-time order when written."""

    entries: list[Entry]

    def copy(self) -> Scene:
        return copy.deepcopy(self)

    def of(self, topic: str) -> list[Entry]:
        return [e for e in self.entries if e.topic == topic]

    def write(self, path: Path, storage: str = "mcap", compression: bool = True) -> Path:
        """Write as a rosbag2 directory (storage 'mcap' or 'sqlite3') or, for storage 'ros1', a .bag file."""
        if storage == "ros1":
            return _write_ros1(self, path)
        plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
        writer = Writer(path, version=9, storage_plugin=plugin)
        if storage == "mcap" and compression:
            writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
        with writer:
            conns: dict[str, Any] = {}
            for entry in sorted(self.entries, key=lambda e: e.log_ns):
                msgtype, msg = to_message(ROS2, entry)
                if entry.topic not in conns:
                    conns[entry.topic] = writer.add_connection(entry.topic, msgtype, typestore=ROS2)
                writer.write(conns[entry.topic], entry.log_ns, ROS2.serialize_cdr(msg, msgtype))
        return path


def make_scene(duration_s: float = 6.0, t0_ns: int = T0) -> Scene:
    """The undamaged scene: tf 20 Hz (odom->base_link) and 5 Hz (map->odom), scans 5 Hz, clouds 1 Hz,
    /odom and /ground_truth 20 Hz, one /tf_static message (base_link -> base_scan, camera_link)."""
    entries: list[Entry] = []
    static = [Tf(t0_ns, "base_link", "base_scan", BASE_TO_SCAN, (0.0, 0.0, 0.0, 1.0)),
              Tf(t0_ns, "base_link", "camera_link", BASE_TO_CAMERA, (0.0, 0.0, 0.0, 1.0))]
    entries.append(Entry("/tf_static", t0_ns, static))
    odom_in_map = MAP_TO_ODOM
    map_in_odom = _inverse(odom_in_map)
    n20 = int(duration_s * 20) + 1
    for i in range(n20):
        t_s = i / 20
        stamp = t0_ns + i * (S // 20)
        x, y, yaw = robot_pose(t_s)
        ox, oy, oyaw = _compose(map_in_odom, (x, y, yaw))
        entries.append(Entry("/tf", stamp + 1_000_000, [Tf(stamp, "odom", "base_link", (ox, oy, 0.0), yaw_quat(oyaw))]))
        entries.append(Entry("/odom", stamp + 1_000_000, Odom(stamp, "odom", "base_link", (ox, oy, 0.0), yaw_quat(oyaw),
                                                              (0.25, 0.0, 0.0), (0.0, 0.0, 0.0))))
        entries.append(Entry("/ground_truth", stamp + 1_500_000,
                             Odom(stamp, "map", "base_link", (x, y, 0.0), yaw_quat(yaw))))
        if i % 4 == 0:
            mx, my, myaw = odom_in_map
            entries.append(Entry("/tf", stamp + 2_000_000, [Tf(stamp, "map", "odom", (mx, my, 0.0), yaw_quat(myaw))]))
        if i % 4 == 2:
            entries.append(Entry("/scan", stamp + 20_000_000, make_scan_at(stamp, t_s)))
        if i % 20 == 10:
            entries.append(Entry("/camera/depth/points", stamp + 40_000_000, make_cloud_at(stamp, t_s)))
    entries.sort(key=lambda e: e.log_ns)
    return Scene(entries)


def make_scan_at(stamp_ns: int, t_s: float, n: int = 360) -> Scan:
    """A 360-beam scan of the room from the robot's pose at ``t_s``."""
    x, y, yaw = robot_pose(t_s)
    sx, sy, syaw = _compose((x, y, yaw), (BASE_TO_SCAN[0], BASE_TO_SCAN[1], 0.0))
    inc = 2 * math.pi / n
    angle_min = -math.pi
    angles = angle_min + inc * np.arange(n)
    ranges = raycast((sx, sy), angles + syaw, 8.0).astype(np.float32)
    return Scan(stamp_ns, "base_scan", angle_min, angle_min + inc * (n - 1), inc, 0.12, 8.0, ranges)


def make_cloud_at(stamp_ns: int, t_s: float) -> Cloud:
    """Wall points within 5 m in front of the camera, in camera_link (x forward)."""
    x, y, yaw = robot_pose(t_s)
    cx, cy, cyaw = _compose((x, y, yaw), (BASE_TO_CAMERA[0], BASE_TO_CAMERA[1], 0.0))
    rel = _WALLS[:, :2] - (cx, cy)
    c, s = math.cos(cyaw), math.sin(cyaw)
    local = np.column_stack((c * rel[:, 0] + s * rel[:, 1], -s * rel[:, 0] + c * rel[:, 1],
                             _WALLS[:, 2] - BASE_TO_CAMERA[2]))
    keep = (local[:, 0] > 0.2) & (np.abs(local[:, 1]) < local[:, 0]) & (np.hypot(local[:, 0], local[:, 1]) < 5)
    return Cloud(stamp_ns, "camera_link", local[keep])


# ---------------------------------------------------------------------------- messages


def _header(ts: Any, stamp_ns: int, frame_id: str) -> Any:
    T = ts.types
    stamp = T["builtin_interfaces/msg/Time"](sec=stamp_ns // S, nanosec=stamp_ns % S)
    names = {f.name for f in dataclasses.fields(T["std_msgs/msg/Header"])}
    if "seq" in names:
        return T["std_msgs/msg/Header"](seq=0, stamp=stamp, frame_id=frame_id)
    return T["std_msgs/msg/Header"](stamp=stamp, frame_id=frame_id)


def _tf_msg(ts: Any, transforms: list[Tf]) -> Any:
    T = ts.types
    items = []
    for tf in transforms:
        items.append(T["geometry_msgs/msg/TransformStamped"](
            header=_header(ts, tf.stamp_ns, tf.parent), child_frame_id=tf.child,
            transform=T["geometry_msgs/msg/Transform"](
                translation=T["geometry_msgs/msg/Vector3"](x=float(tf.xyz[0]), y=float(tf.xyz[1]), z=float(tf.xyz[2])),
                rotation=T["geometry_msgs/msg/Quaternion"](x=float(tf.quat_xyzw[0]), y=float(tf.quat_xyzw[1]),
                                                           z=float(tf.quat_xyzw[2]), w=float(tf.quat_xyzw[3])))))
    return T["tf2_msgs/msg/TFMessage"](transforms=items)


def _scan_msg(ts: Any, scan: Scan) -> Any:
    T = ts.types
    return T["sensor_msgs/msg/LaserScan"](
        header=_header(ts, scan.stamp_ns, scan.frame_id), angle_min=float(scan.angle_min),
        angle_max=float(scan.angle_max), angle_increment=float(scan.angle_increment), time_increment=0.0,
        scan_time=0.2, range_min=float(scan.range_min), range_max=float(scan.range_max),
        ranges=np.asarray(scan.ranges, dtype=np.float32), intensities=np.zeros(0, dtype=np.float32))


def _odom_msg(ts: Any, odom: Odom) -> Any:
    T = ts.types
    v3 = T["geometry_msgs/msg/Vector3"]
    return T["nav_msgs/msg/Odometry"](
        header=_header(ts, odom.stamp_ns, odom.frame_id), child_frame_id=odom.child,
        pose=T["geometry_msgs/msg/PoseWithCovariance"](
            pose=T["geometry_msgs/msg/Pose"](
                position=T["geometry_msgs/msg/Point"](x=float(odom.xyz[0]), y=float(odom.xyz[1]), z=float(odom.xyz[2])),
                orientation=T["geometry_msgs/msg/Quaternion"](x=float(odom.quat_xyzw[0]), y=float(odom.quat_xyzw[1]),
                                                              z=float(odom.quat_xyzw[2]), w=float(odom.quat_xyzw[3]))),
            covariance=np.zeros(36, dtype=np.float64)),
        twist=T["geometry_msgs/msg/TwistWithCovariance"](
            twist=T["geometry_msgs/msg/Twist"](linear=v3(x=odom.linear[0], y=odom.linear[1], z=odom.linear[2]),
                                               angular=v3(x=odom.angular[0], y=odom.angular[1], z=odom.angular[2])),
            covariance=np.zeros(36, dtype=np.float64)))


def _cloud_msg(ts: Any, cloud: Cloud) -> Any:
    T = ts.types
    xyz = np.asarray(cloud.xyz, dtype=np.float64).reshape(-1, 3)
    n = xyz.shape[0]
    step = max(cloud.point_step, 12)
    order = ">" if cloud.bigendian_data else "<"
    rec = np.zeros(n, dtype=np.dtype({"names": list("xyz"), "formats": [order + "f4"] * 3,
                                      "offsets": [0, 4, 8], "itemsize": step}))
    for i, name in enumerate("xyz"):
        rec[name] = xyz[:, i]
    data = rec.view(np.uint8).reshape(-1)
    fields = [T["sensor_msgs/msg/PointField"](name=nm, offset=4 * i, datatype=7, count=1) for i, nm in enumerate("xyz")]
    msg = T["sensor_msgs/msg/PointCloud2"](
        header=_header(ts, cloud.stamp_ns, cloud.frame_id), height=1, width=n, fields=fields,
        is_bigendian=cloud.bigendian_data, point_step=step, row_step=n * step, data=data, is_dense=False)
    if cloud.overrides:
        overrides = dict(cloud.overrides)
        if "fields" in overrides:  # [(name, offset, datatype, count)]
            overrides["fields"] = [T["sensor_msgs/msg/PointField"](name=nm, offset=o, datatype=d, count=c)
                                   for nm, o, d, c in overrides["fields"]]
        msg = dataclasses.replace(msg, **overrides)
    return msg


def to_message(ts: Any, entry: Entry) -> tuple[str, Any]:
    """(msgtype, rosbags message) of an entry."""
    item = entry.item
    if entry.raw_type is not None:
        return entry.raw_type, item
    if isinstance(item, list):
        return "tf2_msgs/msg/TFMessage", _tf_msg(ts, item)
    if isinstance(item, Scan):
        return "sensor_msgs/msg/LaserScan", _scan_msg(ts, item)
    if isinstance(item, Odom):
        return "nav_msgs/msg/Odometry", _odom_msg(ts, item)
    if isinstance(item, Cloud):
        return "sensor_msgs/msg/PointCloud2", _cloud_msg(ts, item)
    raise TypeError(f"unknown scene item {type(item)}")


_ROS1: Any = None


def _ros1_typestore() -> Any:
    global _ROS1
    if _ROS1 is None:
        _ROS1 = get_typestore(Stores.ROS1_NOETIC)
        _ROS1.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms", "tf2_msgs/msg/TFMessage"))
    return _ROS1


def _write_ros1(scene: Scene, path: Path) -> Path:
    from rosbags.rosbag1 import Writer as Writer1

    ts = _ros1_typestore()
    with Writer1(path) as writer:
        conns: dict[str, Any] = {}
        for entry in sorted(scene.entries, key=lambda e: e.log_ns):
            msgtype, msg = to_message(ts, entry)
            if entry.topic not in conns:
                conns[entry.topic] = writer.add_connection(entry.topic, msgtype, typestore=ts)
            writer.write(conns[entry.topic], entry.log_ns, ts.serialize_ros1(msg, msgtype))
    return path


# ---------------------------------------------------------------------------- edits used by the corpus


def edit(scene: Scene, topic: str, fn: Callable[[Any], None], which: str = "one") -> Scene:
    """A copy of ``scene`` with ``fn`` applied to the items of ``topic``: the middle one ('one') or 'all'."""
    out = scene.copy()
    entries = out.of(topic)
    targets = entries if which == "all" else [entries[len(entries) // 2]]
    for entry in targets:
        if isinstance(entry.item, list):
            for tf in entry.item:
                fn(tf)
        else:
            fn(entry.item)
    return out
