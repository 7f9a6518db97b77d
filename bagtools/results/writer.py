"""``results.mcap``: what a command computed, as a ROS 2 bag that opens in Foxglove with no set-up.

One MCAP file (profile ``ros2``, CDR messages, ``ros2msg`` schemas embedded,
zstd chunks, indexed) that ``ros2 bag play`` (Humble, Jazzy) and Foxglove read
as they read a recording. Usage::

    with ResultsBag(staged / RESULTS_MCAP) as bag:
        bag.occupancy_grid(grid, frame="map")                                   # /map, latched
        bag.path("/trajectory", stamps_ns, T_map_base, frame="map")             # nav_msgs/Path, latched
        bag.robot("map", "base_footprint", stamps_ns, T_map_base, {"base_scan": T_base_scan})  # /tf, /tf_static
        bag.scans("/scan", scans)                                               # LaserScans at their stamps
        bag.markers("/loop_closures", "map", [Markers("loops", "line_list", endpoints_m)])

Time: messages that describe the whole run (maps, paths, clouds, markers,
/tf_static) are written once at the start time (the earliest stamp of the
timed messages, or ``start_ns``), with transient-local ("latched") QoS, so
they are there wherever one scrubs; timed messages (/tf, scans) are written
at their header stamps, so each scan lands on the map at its pose. The file
is written in log-time order when the context exits; on an error nothing
is left at ``path``.

QoS: each channel's ``offered_qos_profiles`` is in rosbag2's metadata-version-8
form (integer enums), which Humble and Jazzy both read; a ``rosbag2``
metadata record names the distro whose message definitions are embedded.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import Any, Literal

import numpy as np
from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime
from rosbags.interfaces.typing import Nodetype
from rosbags.rosbag2.metadata import dump_qos_v8
from rosbags.typesys import Stores, get_typestore

from bagtools import __version__
from bagtools.errors import BagtoolsError
from bagtools.io.decode import LaserScanArrays
from bagtools.transforms import quat2xyzw, tform2quat

RESULTS_MCAP = "results.mcap"


def run_outputs(names: list[str], mcap: bool) -> list[str]:
    """The files a run writes of a command's ``names``: without results.mcap when the run writes none, so that
    ``--force`` replaces (and removes as stale) only what the run itself writes."""
    return [n for n in names if mcap or n != RESULTS_MCAP]
"""The file name every mapping command writes its results bag under."""

_STORES = {"humble": Stores.ROS2_HUMBLE, "jazzy": Stores.ROS2_JAZZY}
_INFINITE = QosTime(sec=9223372036, nsec=854775807)  # rosbag2's "no deadline/lifespan"


def _qos(transient_local: bool, depth: int) -> Qos:
    return Qos(history=QosHistory.KEEP_LAST, depth=depth, reliability=QosReliability.RELIABLE,
               durability=QosDurability.TRANSIENT_LOCAL if transient_local else QosDurability.VOLATILE,
               deadline=_INFINITE, lifespan=_INFINITE, liveliness=QosLiveliness.AUTOMATIC,
               liveliness_lease_duration=_INFINITE, avoid_ros_namespace_conventions=False)


#: Published once and kept for late subscribers (map_server's and tf2's static broadcaster's profile).
LATCHED = _qos(True, 1)
#: /tf as tf2's broadcaster offers it.
TF_QOS = _qos(False, 100)
#: Scans and clouds: reliable (both reliable and best-effort subscribers match), volatile.
STREAM_QOS = _qos(False, 10)

MarkerKind = Literal["line_list", "line_strip", "sphere_list", "points", "cube_list"]
_MARKER_TYPES = {"line_strip": 4, "line_list": 5, "cube_list": 6, "sphere_list": 7, "points": 8}


@dataclass(frozen=True)
class Markers:
    """One visualization_msgs/Marker of many points: lines (pairs for ``line_list``), spheres, cubes or points.

    ``points_m`` (N,3) or (N,2) in the marker array's frame; ``rgba`` in [0, 1];
    ``scale_m`` is the line width or the sphere/cube/point size; ``colors``
    (N,4) in [0, 1] colours each point (optional).
    """

    ns: str
    kind: MarkerKind
    points_m: np.ndarray
    rgba: tuple[float, float, float, float] = (1.0, 0.2, 0.2, 1.0)
    scale_m: float = 0.03
    id: int = 0
    colors: np.ndarray | None = None


@dataclass
class _Entry:
    log_time_ns: int | None  # None: at the start time
    order: int
    topic: str
    build: Callable[[int], Any]  # start time -> message object


def _split_ns(stamp_ns: int) -> tuple[int, int]:
    sec, nanosec = divmod(int(stamp_ns), 1_000_000_000)
    return sec, nanosec


def _as_tforms(T: np.ndarray, n: int | None = None) -> np.ndarray:
    T = np.asarray(T, dtype=np.float64)
    T = T.reshape(-1, 4, 4)
    if n is not None and T.shape[0] != n:
        raise ValueError(f"expected {n} poses, got {T.shape[0]}")
    if not np.isfinite(T).all():
        raise ValueError("poses must be finite")
    return T


class ResultsBag:
    """Collects a command's results and writes them as one ROS 2 MCAP at ``path`` on a clean exit (see the module).

    Args:
        path: the file to write (normally inside a command's staged :class:`~bagtools.outputs.OutputDir`).
        ros_distro: whose message definitions to embed and name ('humble' or 'jazzy'; the types used
            here are the same in both).
        start_ns: when the latched messages are stamped; default the earliest timed stamp.
        namespace: the frames the results move (the robot's base and sensors, and the scans and clouds in
            them) are published as ``NAMESPACE/frame``: opened or played beside the recording, whose tf has
            the same frames under other parents (``map -> odom -> base_footprint`` against the estimate's
            ``map -> base_footprint``), no frame has two parents. The roots (``map``, ``odom``) keep their names.
    """

    def __init__(self, path: str | Path, ros_distro: str = "humble", start_ns: int | None = None,
                 namespace: str | None = None) -> None:
        if ros_distro not in _STORES:
            raise BagtoolsError(f"unknown ROS distro {ros_distro!r} (choose from {', '.join(_STORES)})")
        self.file = Path(path)
        self.ros_distro = ros_distro
        self.start_ns = start_ns
        self.ts = get_typestore(_STORES[ros_distro])
        self.types = self.ts.types
        self._entries: list[_Entry] = []
        self._topics: dict[str, tuple[str, Qos]] = {}
        self.counts: dict[str, int] = {}
        self.namespace = namespace.strip("/") if namespace else None

    def own(self, frame: str) -> str:
        """The name ``frame`` is published under when the results move it (see ``namespace``)."""
        return f"{self.namespace}/{frame}" if self.namespace and frame else frame

    # -- context -----------------------------------------------------------------

    def __enter__(self) -> ResultsBag:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        if exc_type is None:
            self.write()

    # -- what a results bag holds ------------------------------------------------------

    def occupancy_grid(self, grid: Any, frame: str, topic: str = "/map") -> None:
        """An occupancy grid (:class:`~bagtools.grid.OccupancyGrid`) as nav_msgs/OccupancyGrid, latched.

        Cells 100 occupied, 0 free, -1 unknown (what nav2's map_server publishes
        for a trinary map); row 0 of ``data`` at the grid's origin, the lower-left
        corner (``info.origin``), in ``frame``; ``info.resolution`` in metres per cell.
        """
        ternary = np.asarray(grid.occupancy_matrix("ternary"))
        values = np.full(ternary.shape, -1, dtype=np.int8)
        values[ternary == 1] = 100
        values[ternary == 0] = 0
        data = np.ascontiguousarray(np.flipud(values)).reshape(-1)  # image rows run down; the message's run up
        rows, cols = ternary.shape
        x0, y0 = (float(v) for v in grid.grid_location_in_world)
        resolution = float(grid.cell_size_m)
        t = self.types

        def build(start_ns: int) -> Any:
            info = t["nav_msgs/msg/MapMetaData"](
                map_load_time=self._time(start_ns), resolution=resolution, width=cols, height=rows,
                origin=self._pose(np.array([x0, y0, 0.0]), np.array([0.0, 0.0, 0.0, 1.0])))
            return t["nav_msgs/msg/OccupancyGrid"](header=self._header(start_ns, frame), info=info, data=data)

        self._add(topic, "nav_msgs/msg/OccupancyGrid", LATCHED, None, build)

    def path(self, topic: str, stamps_ns: np.ndarray, T_frame_body: np.ndarray, frame: str) -> None:
        """A trajectory as nav_msgs/Path in ``frame`` (each pose stamped), latched. ``T_frame_body`` (N,4,4)."""
        stamps = np.asarray(stamps_ns, dtype=np.int64).reshape(-1)
        T = _as_tforms(T_frame_body, stamps.size)
        xyz, q = T[:, :3, 3].copy(), quat2xyzw(tform2quat(T)) if len(T) else np.empty((0, 4))
        t = self.types

        def build(start_ns: int) -> Any:
            poses = [t["geometry_msgs/msg/PoseStamped"](header=self._header(int(s), frame), pose=self._pose(p, r))
                     for s, p, r in zip(stamps, xyz, q)]
            return t["nav_msgs/msg/Path"](header=self._header(start_ns, frame), poses=poses)

        self._add(topic, "nav_msgs/msg/Path", LATCHED, None, build)

    def point_cloud(self, topic: str, points: np.ndarray, frame: str, intensity: np.ndarray | None = None,
                    rgb: np.ndarray | None = None) -> None:
        """A cloud (N,3) in ``frame`` as one sensor_msgs/PointCloud2, latched (fields x y z [intensity] [rgb])."""
        fields, data, n = self._cloud_data(points, intensity, rgb)

        def build(start_ns: int) -> Any:
            return self._cloud_msg(start_ns, frame, fields, data, n)

        self._add(topic, "sensor_msgs/msg/PointCloud2", LATCHED, None, build)

    def clouds(self, topic: str,
               clouds: Iterable[tuple[int, str, np.ndarray, np.ndarray | None, np.ndarray | None]]) -> None:
        """PointCloud2 messages at their stamps: (stamp_ns, frame_id, points (N,3), intensity (N,) or None, rgb (N,3) or
        None), in their sensor's frame (``own``: namespaced)."""
        for stamp_ns, frame, points, intensity, rgb in clouds:
            frame = self.own(frame)
            fields, data, n = self._cloud_data(points, intensity, rgb)
            self._add(topic, "sensor_msgs/msg/PointCloud2", STREAM_QOS, int(stamp_ns),
                      lambda _s, st=int(stamp_ns), f=frame, fl=fields, d=data, k=n: self._cloud_msg(st, f, fl, d, k))

    def scans(self, topic: str, scans: Iterable[LaserScanArrays]) -> None:
        """sensor_msgs/LaserScan messages at their header stamps, in their own frames (``own``: namespaced), as
        decoded."""
        for scan in scans:
            self._add(topic, "sensor_msgs/msg/LaserScan", STREAM_QOS, int(scan.stamp_ns),
                      lambda _s, sc=scan: self._scan_msg(sc))

    def tf_static(self, transforms: Sequence[tuple[str, str, np.ndarray]]) -> None:
        """Static transforms (parent, child, T_parent_child (4,4)) as one tf2_msgs/TFMessage on /tf_static, latched."""
        items = [(parent, child, _as_tforms(T)[0]) for parent, child, T in transforms]
        if not items:
            return

        def build(start_ns: int) -> Any:
            return self.types["tf2_msgs/msg/TFMessage"](
                transforms=[self._transform(start_ns, parent, child, T) for parent, child, T in items])

        self._add("/tf_static", "tf2_msgs/msg/TFMessage", LATCHED, None, build)

    def tf(self, parent: str, child: str, stamps_ns: np.ndarray, T_parent_child: np.ndarray) -> None:
        """A moving frame: one tf2_msgs/TFMessage on /tf per stamp, T_parent_child (N,4,4)."""
        stamps = np.asarray(stamps_ns, dtype=np.int64).reshape(-1)
        T = _as_tforms(T_parent_child, stamps.size)
        for stamp, pose in zip(stamps, T):
            self._add("/tf", "tf2_msgs/msg/TFMessage", TF_QOS, int(stamp),
                      lambda _s, st=int(stamp), P=pose: self.types["tf2_msgs/msg/TFMessage"](
                          transforms=[self._transform(st, parent, child, P)]))

    def robot(self, frame: str, base_frame: str | None, stamps_ns: np.ndarray, T_frame_base: np.ndarray,
              sensors: dict[str, np.ndarray] | None = None) -> None:
        """The robot's frames: ``frame`` -> ``base_frame`` on /tf at each stamp, and each sensor frame under the
        base on /tf_static (``sensors``: frame id -> T_base_sensor (4,4); the base itself is skipped); the base
        and sensors namespaced (``own``).

        With ``base_frame`` None the single sensor frame hangs from ``frame`` directly: pass
        T_frame_sensor as ``T_frame_base`` and ``sensors={sensor_frame: identity}``.
        """
        sensors = dict(sensors or {})
        if base_frame is None:
            if len(sensors) != 1:
                raise ValueError("without a base frame, give exactly one sensor frame")
            (sensor, T_base_sensor), = sensors.items()
            self.tf(frame, self.own(sensor), stamps_ns, _as_tforms(T_frame_base) @ _as_tforms(T_base_sensor)[0])
            return
        self.tf(frame, self.own(base_frame), stamps_ns, T_frame_base)
        self.tf_static([(self.own(base_frame), self.own(sensor), T) for sensor, T in sensors.items()
                        if sensor and sensor != base_frame])

    def markers(self, topic: str, frame: str, markers: Sequence[Markers], stamp_ns: int | None = None) -> None:
        """visualization_msgs/MarkerArray of ``markers`` in ``frame``, latched (at ``stamp_ns`` if given, else at the start)."""
        specs = list(markers)

        def build(start_ns: int) -> Any:
            when = start_ns if stamp_ns is None else int(stamp_ns)
            return self.types["visualization_msgs/msg/MarkerArray"](
                markers=[self._marker(when, frame, m) for m in specs])

        self._add(topic, "visualization_msgs/msg/MarkerArray", LATCHED, None if stamp_ns is None else int(stamp_ns),
                  build)

    # -- writing -----------------------------------------------------------------

    def write(self) -> Path:
        """Write every message collected, in log-time order; returns the path. Nothing is left on an error."""
        from mcap import __version__ as mcap_version
        from mcap.writer import CompressionType, Writer

        timed = [e.log_time_ns for e in self._entries if e.log_time_ns is not None]
        start = self.start_ns if self.start_ns is not None else (min(timed) if timed else 0)
        entries = sorted(self._entries, key=lambda e: (start if e.log_time_ns is None else e.log_time_ns, e.order))
        try:
            with open(self.file, "wb") as stream:
                writer = Writer(stream, compression=CompressionType.ZSTD, chunk_size=4 * 1024 * 1024)
                writer.start(profile="ros2", library=f"bagtools {__version__}; mcap-python {mcap_version}")
                channels = self._register(writer)
                for entry in entries:
                    when = start if entry.log_time_ns is None else entry.log_time_ns
                    message = entry.build(start)
                    data = bytes(self.ts.serialize_cdr(message, message.__msgtype__))
                    writer.add_message(channels[entry.topic], log_time=when, data=data, publish_time=when)
                writer.add_metadata("rosbag2", {"ROS_DISTRO": self.ros_distro})
                writer.finish()
        except BaseException:
            self.file.unlink(missing_ok=True)
            raise
        return self.file

    def _register(self, writer: Any) -> dict[str, int]:
        schema_ids: dict[str, int] = {}
        channels: dict[str, int] = {}
        for topic, (msgtype, qos) in self._topics.items():
            if msgtype not in schema_ids:
                text, _ = self.ts.generate_msgdef(msgtype, ros_version=2)
                schema_ids[msgtype] = writer.register_schema(msgtype, "ros2msg", text.encode("utf-8"))
            metadata = {"offered_qos_profiles": dump_qos_v8([qos]),
                        "topic_type_hash": self.ts.hash_rihs01(msgtype)}
            channels[topic] = writer.register_channel(topic, "cdr", schema_ids[msgtype], metadata)
        return channels

    # -- building messages ------------------------------------------------------------

    def _add(self, topic: str, msgtype: str, qos: Qos, log_time_ns: int | None, build: Callable[[int], Any]) -> None:
        known = self._topics.setdefault(topic, (msgtype, qos))
        if known[0] != msgtype:
            raise ValueError(f"{topic} already holds {known[0]}, not {msgtype}")
        if log_time_ns is not None and log_time_ns < 0:
            raise ValueError(f"{topic}: negative stamp {log_time_ns}")
        self._entries.append(_Entry(log_time_ns, len(self._entries), topic, build))
        self.counts[topic] = self.counts.get(topic, 0) + 1

    def _time(self, stamp_ns: int) -> Any:
        sec, nanosec = _split_ns(stamp_ns)
        return self.types["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec)

    def _header(self, stamp_ns: int, frame: str) -> Any:
        return self.types["std_msgs/msg/Header"](stamp=self._time(stamp_ns), frame_id=frame)

    def _pose(self, xyz: np.ndarray, q_xyzw: np.ndarray) -> Any:
        t = self.types
        return t["geometry_msgs/msg/Pose"](
            position=t["geometry_msgs/msg/Point"](x=float(xyz[0]), y=float(xyz[1]), z=float(xyz[2])),
            orientation=t["geometry_msgs/msg/Quaternion"](x=float(q_xyzw[0]), y=float(q_xyzw[1]), z=float(q_xyzw[2]),
                                                           w=float(q_xyzw[3])))

    def _transform(self, stamp_ns: int, parent: str, child: str, T: np.ndarray) -> Any:
        t = self.types
        q = quat2xyzw(tform2quat(T))
        return t["geometry_msgs/msg/TransformStamped"](
            header=self._header(stamp_ns, parent), child_frame_id=child,
            transform=t["geometry_msgs/msg/Transform"](
                translation=t["geometry_msgs/msg/Vector3"](x=float(T[0, 3]), y=float(T[1, 3]), z=float(T[2, 3])),
                rotation=t["geometry_msgs/msg/Quaternion"](x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3]))))

    def _cloud_data(self, points: np.ndarray, intensity: np.ndarray | None,
                    rgb: np.ndarray | None) -> tuple[list[tuple[str, int]], np.ndarray, int]:
        """PointField (name, offset) list (all float32) and the packed little-endian bytes of the points."""
        points = np.asarray(points, dtype=np.float32).reshape(-1, 3)
        n = points.shape[0]
        names = ["x", "y", "z"] + (["intensity"] if intensity is not None else []) + (["rgb"] if rgb is not None else [])
        rec = np.empty(n, dtype=np.dtype({"names": names, "formats": ["<f4"] * (len(names) - (rgb is not None))
                                          + (["<u4"] if rgb is not None else [])}))
        for k, axis in enumerate("xyz"):
            rec[axis] = points[:, k]
        if intensity is not None:
            rec["intensity"] = np.asarray(intensity, dtype=np.float32).reshape(-1)
        if rgb is not None:
            c = np.asarray(rgb, dtype=np.uint32).reshape(-1, 3)
            rec["rgb"] = (c[:, 0] << 16) | (c[:, 1] << 8) | c[:, 2]  # PCL's packing in a float32 field
        return [(name, 4 * i) for i, name in enumerate(names)], rec.view(np.uint8).reshape(-1), n

    def _cloud_msg(self, stamp_ns: int, frame: str, fields: list[tuple[str, int]], data: np.ndarray, n: int) -> Any:
        t = self.types
        point_field = t["sensor_msgs/msg/PointField"]
        step = 4 * len(fields)
        return t["sensor_msgs/msg/PointCloud2"](
            header=self._header(stamp_ns, frame), height=1, width=n,
            fields=[point_field(name=name, offset=offset, datatype=point_field.FLOAT32, count=1) for name, offset in fields],
            is_bigendian=False, point_step=step, row_step=step * n, data=data, is_dense=True)

    def _scan_msg(self, scan: LaserScanArrays) -> Any:
        angles = scan.angles_rad
        angle_min = float(angles[0]) if angles.size else 0.0
        angle_max = float(angles[-1]) if angles.size else 0.0
        return self.types["sensor_msgs/msg/LaserScan"](
            header=self._header(scan.stamp_ns, self.own(scan.frame_id)), angle_min=angle_min, angle_max=angle_max,
            angle_increment=float(scan.angle_increment_rad), time_increment=float(scan.time_increment_s),
            scan_time=float(scan.scan_time_s), range_min=float(scan.range_min_m),
            range_max=float(scan.range_max_m) if math.isfinite(scan.range_max_m) else 0.0,
            ranges=np.asarray(scan.ranges_m, dtype=np.float32),
            intensities=np.asarray(scan.intensities, dtype=np.float32))

    def _marker(self, stamp_ns: int, frame: str, spec: Markers) -> Any:
        t = self.types
        points = np.asarray(spec.points_m, dtype=np.float64)
        if points.ndim != 2 or points.shape[1] not in (2, 3):
            raise ValueError(f"marker points must be (N,2) or (N,3), got shape {points.shape}")
        if points.shape[1] == 2:
            points = np.column_stack([points, np.zeros(len(points))])
        color = t["std_msgs/msg/ColorRGBA"]
        r, g, b, a = (float(v) for v in spec.rgba)
        scale = float(spec.scale_m)
        return _with_defaults(
            self.ts, "visualization_msgs/msg/Marker", header=self._header(stamp_ns, frame), ns=spec.ns, id=int(spec.id),
            type=_MARKER_TYPES[spec.kind], action=0,
            pose=self._pose(np.zeros(3), np.array([0.0, 0.0, 0.0, 1.0])),
            scale=t["geometry_msgs/msg/Vector3"](x=scale, y=scale, z=scale),
            color=color(r=r, g=g, b=b, a=a),
            points=[t["geometry_msgs/msg/Point"](x=float(p[0]), y=float(p[1]), z=float(p[2])) for p in points],
            colors=[] if spec.colors is None else [color(r=float(c[0]), g=float(c[1]), b=float(c[2]), a=float(c[3]))
                                                   for c in np.asarray(spec.colors, dtype=np.float64)])


_NUMPY_KINDS = {"bool": np.bool_, "int8": np.int8, "uint8": np.uint8, "byte": np.uint8, "char": np.uint8,
                "int16": np.int16, "uint16": np.uint16, "int32": np.int32, "uint32": np.uint32, "int64": np.int64,
                "uint64": np.uint64, "float32": np.float32, "float64": np.float64}


def _default_of(ts: Any, node: tuple) -> Any:
    """The zero value of one field definition of a rosbags typestore."""
    kind, detail = node
    if kind == Nodetype.BASE:
        name = detail[0]
        return "" if name in ("string", "wstring") else (False if name == "bool" else (0.0 if "float" in name else 0))
    if kind == Nodetype.NAME:
        return _with_defaults(ts, detail)
    inner, size = detail
    if inner[0] == Nodetype.BASE and inner[1][0] in _NUMPY_KINDS:
        return np.zeros(size if kind == Nodetype.ARRAY else 0, dtype=_NUMPY_KINDS[inner[1][0]])
    return [_default_of(ts, inner) for _ in range(size if kind == Nodetype.ARRAY else 0)]


def _with_defaults(ts: Any, msgtype: str, **fields: Any) -> Any:
    """A message of ``msgtype`` with ``fields`` set and every other field at its zero value."""
    _, defs = ts.fielddefs[msgtype]
    values = {name: fields[name] if name in fields else _default_of(ts, node) for name, node in defs}
    return ts.types[msgtype](**values)
