"""Decoders from rosbags message objects to numpy arrays.

Each decoder takes one deserialized message (ROS 1 or ROS 2: rosbags gives both
the same field names) and returns a small frozen dataclass of arrays. Stamps are
int nanoseconds; quaternions are in ROS order x, y, z, w.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np

from bagtools.errors import BagtoolsError

LASERSCAN_TYPES = ("sensor_msgs/msg/LaserScan",)
POINTCLOUD2_TYPES = ("sensor_msgs/msg/PointCloud2",)
ODOMETRY_TYPES = ("nav_msgs/msg/Odometry",)
POSE_WITH_COVARIANCE_TYPES = ("geometry_msgs/msg/PoseWithCovarianceStamped",)
TF_TYPES = ("tf2_msgs/msg/TFMessage", "tf/msg/tfMessage")

# sensor_msgs/PointField datatypes -> numpy scalar kinds (byte order added later).
_POINTFIELD_DTYPES = {1: "i1", 2: "u1", 3: "i2", 4: "u2", 5: "i4", 6: "u4", 7: "f4", 8: "f8"}


class DecodeError(BagtoolsError):
    """A message cannot be decoded (e.g. a PointCloud2 without x, y, z fields)."""


def stamp_to_ns(stamp: Any) -> int:
    """builtin_interfaces/Time (sec, nanosec) -> int nanoseconds."""
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def sensor_stamp_ns(header: Any, what: str) -> int:
    """A sensor message's header stamp in ns; :class:`DecodeError` for a nanosec field outside [0, 1e9) (no
    time: the stamp would run into the next second) and for a stamp before 1970 (a negative time), which places
    the data nowhere and no bag or MCAP file can hold."""
    nanosec = int(header.stamp.nanosec)
    if not 0 <= nanosec < 1_000_000_000:
        raise DecodeError(f"{what} header stamp has nanosec {nanosec}, outside 0 .. 999999999")
    stamp_ns = stamp_to_ns(header.stamp)
    if stamp_ns < 0:
        raise DecodeError(f"{what} header stamp {stamp_ns / 1e9:.9f} s is negative")
    return stamp_ns


#: Returns beyond this are not believed, whatever a scan's range_max says (no 2D laser reaches 1 km).
MAX_PLAUSIBLE_RANGE_M = 1000.0
#: Cloud points farther than this from their sensor on any axis are damage (or a wrong is_bigendian), not data.
MAX_PLAUSIBLE_COORDINATE_M = 1.0e5


@dataclass(frozen=True, slots=True)  # slots: a bag's scans are made by the thousand, and twice as fast so
class LaserScanArrays:
    """A LaserScan as arrays, in the scan's own frame.

    ``ranges_m`` (N,) float32 as recorded (inf/NaN kept); ``angles_rad`` (N,)
    float64, beam i at angle_min + i * angle_increment (read-only, shared
    between scans of the same geometry); ``range_min_m`` and ``range_max_m``
    are the message's limits made sane (at least 0, at most
    :data:`MAX_PLAUSIBLE_RANGE_M`); ``valid`` (N,) bool: finite, above 0 and
    within them. ``angle_increment_rad``, ``time_increment_s`` and ``scan_time_s``
    are the message's. ``notes`` says what in the header was implausible and how it
    was read (empty for a sound scan); the same notes come back for every scan
    of one geometry, so callers can count them.
    """

    stamp_ns: int
    frame_id: str
    ranges_m: np.ndarray
    angles_rad: np.ndarray
    range_min_m: float
    range_max_m: float
    intensities: np.ndarray
    notes: tuple[str, ...] = ()
    angle_increment_rad: float = 0.0
    time_increment_s: float = 0.0
    scan_time_s: float = 0.0

    @property
    def valid(self) -> np.ndarray:
        r = self.ranges_m
        with np.errstate(invalid="ignore"):
            return (r > 0) & (r >= self.range_min_m) & (r <= self.range_max_m)

    def points_xy(self) -> np.ndarray:
        """(M,2) float64 x, y of the valid returns in the scan frame, metres."""
        keep = self.valid
        r = self.ranges_m[keep].astype(np.float64)
        a = self.angles_rad[keep]
        return np.column_stack((r * np.cos(a), r * np.sin(a)))


@lru_cache(maxsize=64)
def _beam_angles(angle_min_rad: float, increment_rad: float, n: int) -> np.ndarray:
    """angle_min + i * increment for i < n, read-only and shared: a scanner repeats its geometry."""
    angles = angle_min_rad + np.arange(n) * increment_rad
    angles.flags.writeable = False
    return angles


@lru_cache(maxsize=64)
def _scan_geometry(angle_min: float, increment: float, angle_max: float, n: int, range_min: float,
                   range_max: float) -> tuple[np.ndarray, float, float, tuple[str, ...]]:
    """Beam angles, sane range limits and notes for one LaserScan geometry; raises DecodeError if unusable."""
    if not (math.isfinite(angle_min) and math.isfinite(increment)):
        raise DecodeError(f"LaserScan angle_min {angle_min} or angle_increment {increment} is not finite")
    if n > 1 and increment == 0.0:
        raise DecodeError(f"LaserScan angle_increment is 0: all {n} beams would point the same way")
    notes: list[str] = []
    span = increment * (n - 1)
    if n > 1 and abs(span) > 2 * math.pi * 1.01:
        notes.append(f"beams span {abs(span):.3g} rad, more than a full turn (angle_increment {increment:.4g})")
    header_span = angle_max - angle_min
    if n > 1 and math.isfinite(header_span) and header_span * increment < 0 and abs(header_span) > abs(increment):
        notes.append(f"angle_increment {increment:.4g} has the opposite sign of angle_max - angle_min "
                     f"({header_span:.4g}); beams placed at angle_min + i * angle_increment, as ROS defines them")
    if n > 1 and math.isfinite(angle_max) and abs(angle_min + (n - 1) * increment - angle_max) > 2 * abs(increment) \
            and header_span * increment >= 0:
        notes.append(f"{n} beams at angle_increment {increment:.4g} end at {angle_min + (n - 1) * increment:.4g} rad, "
                     f"not at angle_max {angle_max:.4g}; beams placed at angle_min + i * angle_increment")
    low = range_min if math.isfinite(range_min) and range_min > 0 else 0.0
    if not math.isfinite(range_min) or range_min < 0:
        notes.append(f"range_min {range_min:.4g} m is not a distance; returns of 0 m or less are ignored")
    high = range_max if math.isfinite(range_max) else MAX_PLAUSIBLE_RANGE_M
    if not (high <= MAX_PLAUSIBLE_RANGE_M):
        high = MAX_PLAUSIBLE_RANGE_M
    if not (math.isfinite(range_max) and range_max <= MAX_PLAUSIBLE_RANGE_M):
        notes.append(f"range_max {range_max:.4g} m is implausible; returns beyond {MAX_PLAUSIBLE_RANGE_M:.0f} m are ignored")
    elif high <= low:
        notes.append(f"range_max {range_max:.4g} m is not above range_min {range_min:.4g} m: no return is valid")
    return _beam_angles(angle_min, increment, n), low, high, tuple(notes)


def decode_laserscan(msg: Any) -> LaserScanArrays:
    """sensor_msgs/LaserScan -> :class:`LaserScanArrays` (ranges are not copied).

    Raises :class:`DecodeError` for a geometry no beam can be placed by
    (non-finite angle_min or angle_increment, a zero increment) and for a negative header stamp.
    """
    stamp_ns = sensor_stamp_ns(msg.header, "LaserScan")
    ranges = np.asarray(msg.ranges, dtype=np.float32)
    angles, low, high, notes = _scan_geometry(float(msg.angle_min), float(msg.angle_increment), float(msg.angle_max),
                                              int(ranges.size), float(msg.range_min), float(msg.range_max))
    return LaserScanArrays(
        stamp_ns=stamp_ns,
        frame_id=msg.header.frame_id,
        ranges_m=ranges,
        angles_rad=angles,
        range_min_m=low,
        range_max_m=high,
        intensities=np.asarray(msg.intensities, dtype=np.float32),
        notes=notes,
        angle_increment_rad=float(msg.angle_increment),
        time_increment_s=float(msg.time_increment),
        scan_time_s=float(msg.scan_time),
    )


@dataclass(frozen=True)
class CloudArrays:
    """A PointCloud2's finite x, y, z points: ``points`` (N,3) float32 in ``frame_id``.

    ``intensity`` (N,) float32 and ``rgb`` (N,3) uint8 are the point's
    intensity and colour, aligned with ``points``, when the cloud has them and
    they were asked for (None otherwise). ``n_implausible`` counts finite
    points dropped for a coordinate beyond :data:`MAX_PLAUSIBLE_COORDINATE_M`
    (damage, or data of the other byte order); ``notes`` says what in the
    header disagrees with the data (it was read anyway).
    """

    stamp_ns: int
    frame_id: str
    points: np.ndarray
    n_implausible: int = 0
    notes: tuple[str, ...] = ()
    intensity: np.ndarray | None = None
    rgb: np.ndarray | None = None


def _point_bytes(msg: Any) -> tuple[np.ndarray, int]:
    """The cloud's data as one row of ``point_step`` bytes per point (padded rows skipped), and the point count.

    Raises :class:`DecodeError` for a layout the data cannot hold.
    """
    height, width, point_step, row_step = int(msg.height), int(msg.width), int(msg.point_step), int(msg.row_step)
    n_points = height * width
    data = np.asarray(msg.data, dtype=np.uint8)
    if n_points == 0:
        return data[:0], 0
    if point_step <= 0 or row_step < width * point_step or data.size < (height - 1) * row_step + width * point_step:
        raise DecodeError(
            f"PointCloud2 layout is inconsistent: {height}x{width} points, point_step {point_step}, "
            f"row_step {row_step}, {data.size} data bytes"
        )
    if row_step != width * point_step:  # padded rows: a strided view of the rows (the checks above bound it)
        rows = np.lib.stride_tricks.as_strided(data, shape=(height, width * point_step), strides=(row_step, 1),
                                               writeable=False)
        data = rows.reshape(-1)
    return data, n_points


def _field_view(msg: Any, data: np.ndarray, n_points: int, field: Any, kind: str | None = None) -> np.ndarray | None:
    """(n_points,) view of one scalar PointField (its first element), read as numpy ``kind`` (default: its
    datatype's), or None when unusable (unknown type, not inside the point)."""
    kind = kind or _POINTFIELD_DTYPES.get(int(field.datatype))
    point_step, offset = int(msg.point_step), int(field.offset)
    if kind is None or offset < 0 or offset + int(kind[1:]) > point_step:
        return None
    order = ">" if msg.is_bigendian else "<"
    dtype = np.dtype({"names": ["v"], "formats": [order + kind], "offsets": [offset], "itemsize": point_step})
    return np.frombuffer(data, dtype=dtype, count=n_points)["v"]


#: PointField names read as a point's intensity, in order of preference.
INTENSITY_FIELDS = ("intensity", "intensities", "i", "reflectivity")
#: PointField names of a packed colour (PCL's convention: 0x00RRGGBB in a float32 or uint32).
PACKED_RGB_FIELDS = ("rgb", "rgba")


def _attribute_views(msg: Any, data: np.ndarray, n_points: int) -> tuple[np.ndarray | None, np.ndarray | None]:
    """(intensity (N,) view or None, rgb (N,3) uint8 or None) of every point of the cloud."""
    fields = {f.name: f for f in msg.fields}
    intensity = None
    for name in INTENSITY_FIELDS:
        if name in fields and (intensity := _field_view(msg, data, n_points, fields[name])) is not None:
            break
    rgb = None
    for name in PACKED_RGB_FIELDS:
        field = fields.get(name)
        if field is None or int(field.datatype) not in (6, 7):  # uint32 or float32 holding 0x00RRGGBB
            continue
        packed = _field_view(msg, data, n_points, field, kind="u4")  # a float32's bits are the packed colour
        if packed is not None:
            packed = packed.astype(np.uint32)
            rgb = np.column_stack(((packed >> 16) & 0xFF, (packed >> 8) & 0xFF, packed & 0xFF)).astype(np.uint8)
            break
    if rgb is None and all(c in fields for c in "rgb"):  # separate r, g, b channels: integers 0..255, floats 0..1
        views = [_field_view(msg, data, n_points, fields[c]) for c in "rgb"]
        if all(v is not None for v in views):
            channels = np.column_stack(views).astype(np.float64)
            if views[0].dtype.kind == "f":
                channels = np.nan_to_num(channels * 255.0)
            rgb = np.clip(np.rint(channels), 0, 255).astype(np.uint8)
    return intensity, rgb


def _xyz_records(msg: Any) -> tuple[np.ndarray | None, np.ndarray]:
    """(the points as 1-D structured records whose field ``xyz`` is their (3,) coordinates, or None when x, y
    and z are not one run of one type; the (height*width, 3) view or copy of x, y, z)."""
    fields = {f.name: f for f in msg.fields}
    missing = [n for n in "xyz" if n not in fields]
    if missing:
        raise DecodeError(f"PointCloud2 has no field(s) {', '.join(missing)} (fields: {', '.join(fields) or 'none'})")
    order = ">" if msg.is_bigendian else "<"
    kinds = []
    for name in "xyz":
        kind = _POINTFIELD_DTYPES.get(int(fields[name].datatype))
        if kind is None:
            raise DecodeError(f"PointCloud2 field {name} has unknown datatype {fields[name].datatype}")
        kinds.append(kind)
    point_step = int(msg.point_step)
    data, n_points = _point_bytes(msg)
    if n_points == 0:
        return None, np.empty((0, 3), dtype=np.float32)
    offsets = [int(fields[n].offset) for n in "xyz"]
    for name, offset, kind in zip("xyz", offsets, kinds):
        if offset < 0 or offset + int(kind[1:]) > point_step:
            raise DecodeError(f"PointCloud2 field {name} at offset {offset} ({kind[1:]} bytes) does not fit in "
                              f"point_step {point_step}")
    if kinds[0] == kinds[1] == kinds[2] and offsets == [offsets[0], offsets[0] + int(kinds[0][1:]), offsets[0] + 2 * int(kinds[0][1:])]:
        dtype = np.dtype({"names": ["xyz"], "formats": [(order + kinds[0], 3)], "offsets": [offsets[0]], "itemsize": point_step})
        records = np.frombuffer(data, dtype=dtype, count=n_points)
        return records, records["xyz"]
    dtype = np.dtype({"names": list("xyz"), "formats": [order + k for k in kinds], "offsets": offsets, "itemsize": point_step})
    structured = np.frombuffer(data, dtype=dtype, count=n_points)
    return None, np.column_stack([structured[n] for n in "xyz"])


def decode_pointcloud2(msg: Any, keep_nan: bool = False, attributes: bool = False) -> CloudArrays:
    """sensor_msgs/PointCloud2 -> :class:`CloudArrays` with (N,3) float32 points.

    Honours ``fields`` (x, y, z at any offsets and numeric types), ``point_step``,
    ``row_step`` padding and ``is_bigendian``. Points with a non-finite or
    implausible coordinate are dropped unless ``keep_nan`` (then the result is
    height*width points). With ``attributes``, the points' intensity (a field
    named in :data:`INTENSITY_FIELDS`, any numeric type, as float32) and colour
    (a packed ``rgb``/``rgba`` field, PCL's 0x00RRGGBB in a float32 or uint32,
    or separate ``r``, ``g``, ``b`` fields, as (N,3) uint8) come along, filtered
    like the points. Raises :class:`DecodeError` for a layout the data cannot hold.
    """
    records, xyz = _xyz_records(msg)
    intensity = rgb = None
    if attributes and xyz.shape[0]:
        data, n_points = _point_bytes(msg)
        intensity, rgb = _attribute_views(msg, data, n_points)
    n_implausible = 0
    keep_index = None
    if not keep_nan:
        # Per-column tests and an index gather: about 3x faster than isfinite(xyz).all(1) and a
        # boolean mask on the strided (N,3) view of a padded cloud. NaN fails the test too.
        limit = MAX_PLAUSIBLE_COORDINATE_M
        with np.errstate(invalid="ignore"):
            keep = (np.abs(xyz[:, 0]) <= limit) & (np.abs(xyz[:, 1]) <= limit) & (np.abs(xyz[:, 2]) <= limit)
        # Whole point records are gathered (a copy of point_step bytes each) and x, y, z viewed in them: ten
        # times faster than gathering the (N,3) view's rows, whose stride is not their size. The copy also
        # frees the points from the message's buffer (a whole decompressed chunk).
        gather = (lambda rows: records.take(rows)["xyz"]) if records is not None else (lambda rows: xyz.take(rows, axis=0))
        keep_index = np.flatnonzero(keep)
        if keep_index.size < keep.size:
            n_implausible = int(np.isfinite(gather(np.flatnonzero(~keep))).all(axis=1).sum())
        xyz = gather(keep_index)
    with np.errstate(over="ignore"):  # with keep_nan, float64 beyond float32's range becomes inf
        points = np.asarray(xyz, dtype=np.float32)
        if intensity is not None:
            intensity = np.asarray(intensity if keep_index is None else intensity.take(keep_index), dtype=np.float32)
    if rgb is not None and keep_index is not None:
        rgb = rgb.take(keep_index, axis=0)
    size, expected = len(msg.data), int(msg.height) * int(msg.row_step)
    notes = () if size == expected or int(msg.height) * int(msg.width) == 0 else (
        f"PointCloud2 data holds {size} bytes, not height x row_step = {expected}",)
    return CloudArrays(sensor_stamp_ns(msg.header, "PointCloud2"), msg.header.frame_id, points, n_implausible, notes,
                       intensity, rgb)


@dataclass(frozen=True)
class OdometrySample:
    """A nav_msgs/Odometry: pose of ``child_frame_id`` in ``frame_id``, twist in the child frame.

    ``position_m`` (3,), ``orientation_xyzw`` (4,) ROS order, ``linear_mps`` (3,),
    ``angular_radps`` (3,), covariances (6,6) row-major as in the message.
    """

    stamp_ns: int
    frame_id: str
    child_frame_id: str
    position_m: np.ndarray
    orientation_xyzw: np.ndarray
    linear_mps: np.ndarray
    angular_radps: np.ndarray
    pose_covariance: np.ndarray
    twist_covariance: np.ndarray


def decode_odometry(msg: Any) -> OdometrySample:
    """nav_msgs/Odometry -> :class:`OdometrySample`."""
    p, q = msg.pose.pose.position, msg.pose.pose.orientation
    v, w = msg.twist.twist.linear, msg.twist.twist.angular
    return OdometrySample(
        stamp_ns=stamp_to_ns(msg.header.stamp),
        frame_id=msg.header.frame_id,
        child_frame_id=msg.child_frame_id,
        position_m=np.array([p.x, p.y, p.z]),
        orientation_xyzw=np.array([q.x, q.y, q.z, q.w]),
        linear_mps=np.array([v.x, v.y, v.z]),
        angular_radps=np.array([w.x, w.y, w.z]),
        pose_covariance=np.asarray(msg.pose.covariance, dtype=np.float64).reshape(6, 6),
        twist_covariance=np.asarray(msg.twist.covariance, dtype=np.float64).reshape(6, 6),
    )


@dataclass(frozen=True)
class PoseSample:
    """A geometry_msgs/PoseWithCovarianceStamped (AMCL's ``/amcl_pose``): the pose of the robot in ``frame_id``.

    ``position_m`` (3,), ``orientation_xyzw`` (4,) ROS order, ``covariance`` (6,6) row-major as in the message.
    """

    stamp_ns: int
    frame_id: str
    position_m: np.ndarray
    orientation_xyzw: np.ndarray
    covariance: np.ndarray


def decode_pose_with_covariance(msg: Any) -> PoseSample:
    """geometry_msgs/PoseWithCovarianceStamped -> :class:`PoseSample`."""
    p, q = msg.pose.pose.position, msg.pose.pose.orientation
    return PoseSample(
        stamp_ns=stamp_to_ns(msg.header.stamp),
        frame_id=msg.header.frame_id,
        position_m=np.array([p.x, p.y, p.z]),
        orientation_xyzw=np.array([q.x, q.y, q.z, q.w]),
        covariance=np.asarray(msg.pose.covariance, dtype=np.float64).reshape(6, 6),
    )


@dataclass(frozen=True)
class TfArrays:
    """Transforms as parallel arrays: the pose of ``child[i]`` in ``parent[i]`` at ``stamp_ns[i]``.

    ``parent``/``child`` (N,) str (frame ids exactly as recorded); ``stamp_ns``
    (N,) int64; ``translation`` (N,3) float64 metres; ``rotation_xyzw`` (N,4)
    float64 in ROS order x, y, z, w.
    """

    parent: np.ndarray
    child: np.ndarray
    stamp_ns: np.ndarray
    translation: np.ndarray
    rotation_xyzw: np.ndarray
    publisher: np.ndarray | None = None  # (N,) str: who published each, where the bag says (ROS 1 callerid)

    def __len__(self) -> int:
        return int(self.stamp_ns.size)

    def published_by(self, publisher: str) -> TfArrays:
        """The same transforms, marked as published by ``publisher`` ('' leaves them unmarked)."""
        if not publisher:
            return self
        return TfArrays(self.parent, self.child, self.stamp_ns, self.translation, self.rotation_xyzw,
                        np.full(len(self), publisher, dtype=object))

    @staticmethod
    def empty() -> TfArrays:
        return TfArrays(
            np.empty(0, dtype=object), np.empty(0, dtype=object), np.empty(0, dtype=np.int64),
            np.empty((0, 3)), np.empty((0, 4)),
        )

    def select(self, rows: np.ndarray) -> TfArrays:
        """The transforms at ``rows`` (a bool mask or an index array)."""
        return TfArrays(self.parent[rows], self.child[rows], self.stamp_ns[rows], self.translation[rows],
                        self.rotation_xyzw[rows], None if self.publisher is None else self.publisher[rows])

    @staticmethod
    def concatenate(parts: Iterable[TfArrays]) -> TfArrays:
        """Join several TfArrays end to end."""
        parts = [p for p in parts if len(p)]
        if not parts:
            return TfArrays.empty()
        marked = any(p.publisher is not None for p in parts)
        return TfArrays(
            np.concatenate([p.parent for p in parts]),
            np.concatenate([p.child for p in parts]),
            np.concatenate([p.stamp_ns for p in parts]),
            np.concatenate([p.translation for p in parts]),
            np.concatenate([p.rotation_xyzw for p in parts]),
            np.concatenate([p.publisher if p.publisher is not None else np.full(len(p), "", dtype=object)
                            for p in parts]) if marked else None,
        )


class TfRows(tuple):
    """The transforms of one TFMessage as rows (parent, child, stamp_ns, tx, ty, tz, qx, qy, qz, qw): frame ids as
    recorded, int nanoseconds, metres, a ROS-order quaternion. Collected by the thousand, made arrays once."""


def tf_rows(msg: Any) -> TfRows:
    """tf2_msgs/TFMessage (ROS 2) or tf/tfMessage (ROS 1) -> :class:`TfRows`."""
    rows = []
    for ts in msg.transforms:
        t, q = ts.transform.translation, ts.transform.rotation
        rows.append((ts.header.frame_id, ts.child_frame_id, stamp_to_ns(ts.header.stamp),
                     float(t.x), float(t.y), float(t.z), float(q.x), float(q.y), float(q.z), float(q.w)))
    return TfRows(rows)


def tf_arrays(rows: list[tuple] | TfRows, publishers: list[str] | None = None) -> TfArrays:
    """:class:`TfArrays` of transform rows (see :class:`TfRows`); ``publishers`` (one per row) are kept when
    any is known."""
    n = len(rows)
    if n == 0:
        return TfArrays.empty()
    parent = np.empty(n, dtype=object)
    child = np.empty(n, dtype=object)
    columns = list(zip(*rows))
    parent[:] = columns[0]
    child[:] = columns[1]
    stamps = np.array(columns[2], dtype=np.int64)
    values = np.column_stack([np.asarray(c, dtype=np.float64) for c in columns[3:]])
    marked = None
    if publishers is not None and any(publishers):
        marked = np.empty(n, dtype=object)
        marked[:] = publishers
    return TfArrays(parent, child, stamps, values[:, :3], values[:, 3:], marked)


def decode_tf_message(msg: Any) -> TfArrays:
    """tf2_msgs/TFMessage (ROS 2) or tf/tfMessage (ROS 1) -> :class:`TfArrays`."""
    return tf_arrays(tf_rows(msg))
