"""CARMEN logs (``.clf``, ``.log``, gzipped or not) read as a bag: the classic 2D SLAM datasets as distributed.

What each line becomes (messages in the ROS 1 types, so that ``header.seq`` says the recording order):

- ``ROBOTLASER1``, ``FLASER`` and ``RAWLASER1`` (the front laser) -> ``/scan``; ``ROBOTLASER2``, ``RLASER``
  and ``RAWLASER2`` (the rear laser) -> ``/scan_rear``; ``RAWLASER3``/``RAWLASER4`` -> ``/scan3``/``/scan4``.
  Newer logs carry one scan on several lines (ROBOTLASER1 and FLASER): a topic takes only the first kind of its
  laser that the log holds, in that order. A reading at or beyond the maximum range becomes +inf.
- The odometry pose of a ``FLASER``/``RLASER``/``ROBOTLASER`` line, and each ``ODOM`` line -> ``/odom``
  (nav_msgs/Odometry, ``odom`` -> ``base_link``) and ``/tf`` (odom -> base_link).
- The front laser's mount -> ``/tf_static`` (base_link -> laser, and base_link -> rear_laser turned by pi):
  ``ROBOTLASER1``'s laser pose against its robot pose (the first line's), else ``PARAM robot_frontlaser_offset``
  (metres ahead of the base), else none.
- Stamps are each line's ``ipc_timestamp``, exact to the nanosecond (parsed as decimal text, never a float, in
  C's %g form too: "1.10002e+09"): the benchmarks' ``.relations`` files use them.

Beam angles. ``ROBOTLASER``/``RAWLASER`` lines carry start angle, field of view and angular resolution, used as
they say. ``FLASER``/``RLASER`` lines carry only the beam count: the beams span the field of view (180 degrees, 100
for the 400 and 401 beams of a SICK's 100-degree mode) end to end, fov/(n-1) apart. CARMEN's own layout is 1 and
0.5 degree from -90 for 180 and 360 beams ("last beam ignored"); the Intel log's relations (180 beams) decide
against it: 0.249 m with odometry (Kümmerle's metric) that way, 0.033 m at 1 degree from -89, 0.178 m centred,
0.018 m end to end, as the benchmark's bag. ACES (180 beams) and Freiburg 079 (360) are indifferent. A log that
declares its laser's resolution (``PARAM laser_frontlaser_resolution``/``laser_rearlaser_resolution``, degrees) is
read as CARMEN lays it out, from -fov/2, when the beams fit: FHW's (180 beams, 1 degree) scores 0.149 / 0.126 m
aligned APE that way, 0.174 / 0.198 m end to end. The maximum range of these lines is the laser's no-return
reading found in the log (:meth:`CarmenSource._max_range_of`), else ``PARAM robot_front_laser_max`` (rear), else
:data:`FLASER_MAX_RANGE_M`.
"""

from __future__ import annotations

import gzip
import math
import zlib
from collections import Counter
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from bagtools.io.records import RawRecord, TopicInfo
from bagtools.stamps import seconds_text_to_ns as stamp_text_to_ns  # a line's stamp, exactly

#: Suffixes of a CARMEN log (optionally followed by .gz).
CARMEN_SUFFIXES = (".clf", ".log")
#: A FLASER/RLASER line says no maximum range: SICK LMS lasers of these logs report no return at 81.83-81.91 m.
FLASER_MAX_RANGE_M = 81.83
#: How many FLASER/RLASER lines are read when the log is opened to find the laser's no-return reading.
NO_RETURN_SAMPLE = 500
NO_RETURN_MIN_LINES = 3
#: A laser's no-return reading wavers by a few centimetres (Edmonton's 51.14-51.16, Seattle's 81.87-81.91): readings
#: this close below the largest count as that reading.
NO_RETURN_SPREAD_M = 0.1
#: Frames of the presented bag.
ODOM_FRAME, BASE_FRAME = "odom", "base_link"
SCAN_MSGTYPE, ODOM_MSGTYPE, TF_MSGTYPE = "sensor_msgs/msg/LaserScan", "nav_msgs/msg/Odometry", "tf2_msgs/msg/TFMessage"

#: Laser line kinds per topic, in the order a topic prefers them, and each topic's frame.
_LASERS = {
    "/scan": (("ROBOTLASER1", "FLASER", "RAWLASER1"), "laser"),
    "/scan_rear": (("ROBOTLASER2", "RLASER", "RAWLASER2"), "rear_laser"),
    "/scan3": (("RAWLASER3",), "laser3"),
    "/scan4": (("RAWLASER4",), "laser4"),
}
_TOPIC_OF_KIND = {kind: topic for topic, (kinds, _) in _LASERS.items() for kind in kinds}
_ODOM_KINDS = ("ODOM", "FLASER", "RLASER", "ROBOTLASER1", "ROBOTLASER2")
_KNOWN = set(_TOPIC_OF_KIND) | {"ODOM", "PARAM"}


def _read(path: Path, limit: int | None = None) -> tuple[bytes, bool]:
    """The bytes of a log (gunzipped when named .gz), at most about ``limit``, and whether a gzip stream was cut
    short (what was readable before the cut is returned)."""
    if not path.name.lower().endswith(".gz"):
        with open(path, "rb") as f:
            return (f.read() if limit is None else f.read(limit)), False
    parts: list[bytes] = []
    size = 0
    with gzip.open(path, "rb") as f:
        try:
            while limit is None or size < limit:
                part = f.read1(1 << 20)
                if not part:
                    break
                parts.append(part)
                size += len(part)
        except (EOFError, gzip.BadGzipFile, zlib.error):
            return b"".join(parts), True
    return b"".join(parts), False


def looks_like_carmen(path: Path) -> bool:
    """True if ``path`` is named as a CARMEN log (.clf/.log, optionally .gz) and its first line that is not a
    comment starts with a CARMEN keyword."""
    name = path.name.lower()
    stem = name[:-3] if name.endswith(".gz") else name
    if not stem.endswith(CARMEN_SUFFIXES):
        return False
    try:
        head, _ = _read(path, 65536)
    except OSError:
        return False
    for line in head.splitlines():
        words = line.split()
        if not words or words[0].startswith(b"#"):
            continue
        return words[0].decode("ascii", "replace") in _KNOWN or words[0].isupper()
    return False


@dataclass(frozen=True)
class _Laser:
    """What a laser line says: the scan geometry, ranges, the laser's pose on the robot (where the line says it),
    its stamp (the odometry of the line: :func:`_laser_odometry`)."""

    stamp_ns: int
    start_rad: float
    increment_rad: float
    max_range_m: float
    ranges: np.ndarray
    laser_in_base: tuple[float, float, float] | None  # the laser's pose on the robot, where the line says


def carmen_beam_geometry(n: int, declared_increment: float | None = None) -> tuple[float, float]:
    """(start, increment) in radians of a FLASER/RLASER line of ``n`` beams: its field of view (180 degrees, 100
    for 400 or 401 beams) spanned end to end (module docstring), unless the log declares the laser's resolution
    (``declared_increment``, radians): then that far apart from its start, if they span it to within two beams."""
    fov = math.radians(100.0) if n in (400, 401) else math.pi
    if declared_increment is not None and 0 < declared_increment and \
            fov - 2 * declared_increment - 1e-9 <= (n - 1) * declared_increment <= fov + 1e-9:
        return -fov / 2.0, declared_increment
    return -fov / 2.0, fov / max(n - 1, 1)


def _floats(words: list[bytes]) -> list[float]:
    return [float(w) for w in words]


def _ranges(words: list[bytes]) -> np.ndarray:
    """Readings as float32; one past float32's range (3.4e38) becomes +inf, a no-return reading."""
    with np.errstate(over="ignore"):
        return np.asarray(_floats(words), dtype=np.float32)


#: Stamps as int64 nanoseconds end in the year 2262.
MAX_STAMP_NS = 2**63 - 1


def _stamp(word: bytes) -> int:
    stamp = stamp_text_to_ns(word.decode("ascii", "replace"))
    if not 0 <= stamp <= MAX_STAMP_NS:
        raise ValueError(f"stamp {word.decode('ascii', 'replace')} is outside 0 .. year 2262 (int64 nanoseconds)")
    return stamp


def _field_count(kind: str, words: list[bytes]) -> int:
    """How many fields (after the keyword) a line of ``kind`` must have, from the counts it gives; ValueError for
    a negative count. A line with another number of fields is damaged: its stamp and poses would be read from
    the wrong fields."""
    if kind == "ODOM":
        return 9
    if kind in ("FLASER", "RLASER"):
        n = _count(words[0])
        return n + 10
    n = _count(words[7])
    m = _count(words[8 + n])
    return n + m + (12 if kind.startswith("RAWLASER") else 23)


def _count(word: bytes) -> int:
    n = int(word)
    if n < 0:
        raise ValueError(f"a reading count of {n}")
    return n


def _stamp_index(kind: str, words: list[bytes]) -> int:
    """Where a line's ipc_timestamp is among ``words`` (the line without its keyword), without parsing the rest."""
    if kind == "ODOM":
        return 6
    if kind in ("FLASER", "RLASER"):
        return 7 + int(words[0])
    k = 8 + int(words[7])
    k += 1 + int(words[k])  # the remissions
    return k if kind.startswith("RAWLASER") else k + 11


def _parse_laser(kind: str, words: list[bytes], max_ranges: dict[str, float],
                 increments: dict[str, float] | None = None) -> _Laser:
    """One laser line (``words`` without the keyword); ``max_ranges``: the maximum range of FLASER/RLASER lines,
    which do not say it (:meth:`CarmenSource._max_range_of`); ``increments``: their angular resolution (radians)
    where the log declares it."""
    if kind in ("FLASER", "RLASER"):
        n = int(words[0])
        ranges = _ranges(words[1:1 + n])
        start, increment = carmen_beam_geometry(n, (increments or {}).get(kind))
        max_range = max_ranges.get(kind, FLASER_MAX_RANGE_M)
        return _Laser(_stamp(words[7 + n]), start, increment, max_range, ranges, None)
    # RAWLASERk / ROBOTLASERk: laser_type start_angle fov angular_resolution maximum_range accuracy remission_mode
    start, _fov, increment, max_range = _floats(words[1:5])
    n = int(words[7])
    ranges = _ranges(words[8:8 + n])
    k = 8 + n
    n_remissions = int(words[k])
    k += 1 + n_remissions
    if kind.startswith("RAWLASER"):
        return _Laser(_stamp(words[k]), start, increment, max_range, ranges, None)
    lx, ly, lth, rx, ry, rth = _floats(words[k:k + 6])
    c, s = math.cos(rth), math.sin(rth)
    mount = (c * (lx - rx) + s * (ly - ry), -s * (lx - rx) + c * (ly - ry), math.remainder(lth - rth, 2 * math.pi))
    return _Laser(_stamp(words[k + 11]), start, increment, max_range, ranges, mount)


def _laser_odometry(kind: str, words: list[bytes]) -> tuple[int, tuple[float, float, float]]:
    """(stamp, robot odometry pose) of a FLASER/RLASER/ROBOTLASER line, its ranges left unparsed."""
    if kind in ("FLASER", "RLASER"):
        n = int(words[0])
        x, y, th = _floats(words[4 + n:7 + n])
        return _stamp(words[7 + n]), (x, y, th)
    k = 8 + int(words[7])
    k += 1 + int(words[k])  # the remissions
    x, y, th = _floats(words[k + 3:k + 6])
    return _stamp(words[k + 11]), (x, y, th)


def _parse_odom(words: list[bytes]) -> tuple[int, tuple[float, float, float]]:
    x, y, th = _floats(words[0:3])
    return _stamp(words[6]), (x, y, th)


class CarmenSource:
    """A CARMEN log as a bag source (the interface of :mod:`bagtools.io.sources`).

    The log is read once when opened (kept as its lines: a few tens of MB for the longest benchmark logs) and
    every record is sorted by stamp; a record's raw bytes are its index in its topic's recording order and its
    line, which :meth:`deserializer` turns into a message. Lines that cannot be parsed are skipped and counted
    in ``warnings``.
    """

    #: Each message's header.seq is its line's place among its topic's lines: the recording order.
    seq_is_recording_order = True

    def __init__(self, path: Path) -> None:
        self.path = path
        data, cut = _read(path)
        self._lines = data.splitlines()
        self.warnings: list[str] = []
        if cut:  # the last line may be cut too: it is checked like any other
            self.warnings.append(f"{path}: truncated gzip stream: read the {len(self._lines)} lines before the cut, "
                                 "the rest of the log is lost")
        self.typestore = _typestore()
        self._types = self.typestore.types
        self.params: dict[str, float] = {}  # PARAM lines, as they come (a parameter logged later is not yet known)
        lines: list[tuple[int, str, int]] = []  # (line index, kind, stamp) of the laser and odometry lines
        bad: Counter[str] = Counter()
        unknown: Counter[str] = Counter()
        first_bad = ""
        self._mount: tuple[float, float, float] | None = None
        for i, line in enumerate(self._lines):
            words = line.split()
            if not words or words[0].startswith(b"#"):
                continue
            kind = words[0].decode("ascii", "replace")
            if kind == "PARAM" and len(words) >= 3:
                try:
                    self.params[words[1].decode("ascii", "replace")] = float(words[2])
                except ValueError:
                    pass
                continue
            if kind not in _TOPIC_OF_KIND and kind != "ODOM":
                unknown[kind] += 1
                continue
            text = words[1:]
            try:
                expected = _field_count(kind, text)
                if len(text) != expected:
                    raise ValueError(f"{kind} line has {len(text)} fields where its counts say {expected}")
                at = _stamp_index(kind, text)
                stamp = _parse_odom(text)[0] if kind == "ODOM" else _stamp(text[at])
                if self._mount is None and kind == "ROBOTLASER1":
                    self._mount = _parse_laser(kind, text, {}).laser_in_base
            except (ValueError, IndexError) as err:
                bad[kind] += 1
                first_bad = first_bad or f"line {i + 1}: {err}"
                continue
            lines.append((i, kind, stamp))
        kinds = Counter(kind for _, kind, _ in lines)
        self._max_range = {kind: self._max_range_of(kind, [i for i, k, _ in lines if k == kind])
                           for kind in ("FLASER", "RLASER") if kinds[kind]}
        self._increment = {kind: math.radians(self.params[name]) for kind, name in (
            ("FLASER", "laser_frontlaser_resolution"), ("RLASER", "laser_rearlaser_resolution")) if name in self.params}
        chosen = {topic: next((k for k in pref if kinds[k]), None) for topic, (pref, _) in _LASERS.items()}
        self._kind_of_topic = {t: k for t, k in chosen.items() if k is not None}
        used = set(self._kind_of_topic.values()) | {"ODOM"}
        records: list[tuple[int, int, str, int]] = []  # (stamp, line index, topic, seq)
        seq: Counter[str] = Counter()
        for i, kind, stamp in lines:
            if kind not in used:
                continue
            topics = ["/odom", "/tf"] if kind == "ODOM" else [_TOPIC_OF_KIND[kind]]
            if kind in _ODOM_KINDS[1:]:
                topics += ["/odom", "/tf"]
            for topic in topics:
                records.append((stamp, i, topic, seq[topic]))
                seq[topic] += 1
        if self._mount is None and "robot_frontlaser_offset" in self.params and "/scan" in self._kind_of_topic:
            self._mount = (self.params["robot_frontlaser_offset"], 0.0, 0.0)
        if bad:
            counts = ", ".join(f"{n} {k}" for k, n in bad.items())
            self.warnings.append(f"{path}: {counts} line(s) could not be read and were skipped ({first_bad})")
        if unknown:
            counts = ", ".join(f"{n} {k}" for k, n in unknown.most_common(5))
            self.warnings.append(f"{path}: lines of kinds bagtools does not read were skipped ({counts})")
        records.sort(key=lambda r: (r[0], r[1]))
        if records and self._has_static():
            records.insert(0, (records[0][0], -1, "/tf_static", 0))
        self._records = records
        counts = Counter(r[2] for r in records)
        msgtypes = {"/odom": ODOM_MSGTYPE, "/tf": TF_MSGTYPE, "/tf_static": TF_MSGTYPE}
        self.topics = {t: TopicInfo(t, msgtypes.get(t, SCAN_MSGTYPE), n) for t, n in counts.items()}
        self.start_ns = records[0][0] if records else 0
        self.cdr_topics: set[str] = set()  # a CARMEN line is text, decoded by this source
        self.end_ns = records[-1][0] if records else 0
        self.message_count = len(records)

    def _max_range_of(self, kind: str, indexes: list[int]) -> float:
        """The maximum range of a FLASER/RLASER laser (m), readings at or past it being no return: the laser's
        no-return reading found in its lines, else ``PARAM robot_front_laser_max`` (rear), else FLASER_MAX_RANGE_M.

        A laser reports no return as its largest reading, over and over (50.00 in the ACES log, 81.83 in Intel's,
        81.91 in Freiburg 079's, 51.14-51.16 in Edmonton's): the readings within NO_RETURN_SPREAD_M of the largest
        of the first NO_RETURN_SAMPLE lines are that reading when they come in at least NO_RETURN_MIN_LINES lines
        and no other span as wide above half of it holds more (real far returns spread over metres; a saturated
        one repeats, scan after scan), and lie beyond twice the median reading; the smallest of them is the
        maximum range. The readings outrank the PARAM, which is what the robot was set to use (Edmonton's says
        10 m, and a third of its readings lie between 10 and 51 m), not what the laser can see."""
        side = "front" if kind == "FLASER" else "rear"
        fallback = self.params.get(f"robot_{side}_laser_max", FLASER_MAX_RANGE_M)
        readings = []
        for i in indexes[:NO_RETURN_SAMPLE]:
            words = self._lines[i].split()
            try:
                readings.append(_ranges(words[2:2 + int(words[1])]))
            except (ValueError, IndexError):  # a damaged line: skipped (and said) when read
                continue
        readings = [r[np.isfinite(r)] for r in readings]  # a reading past float32's range is no return, not a range
        top = max((float(r.max(initial=0.0)) for r in readings), default=0.0)
        if len(readings) < NO_RETURN_MIN_LINES or top <= 0:
            return fallback
        low = np.float32(top - NO_RETURN_SPREAD_M)
        lines_at_top = sum(bool((r > low).any()) for r in readings)
        values = np.sort(np.concatenate(readings))
        far = values[values > 0.5 * top]  # holds the largest reading at least
        at_top = len(far) - int(np.searchsorted(far, low, side="right"))
        densest = int((np.searchsorted(far, far + np.float32(NO_RETURN_SPREAD_M), side="right") - np.arange(len(far))).max())
        beyond_most = low > 2.0 * float(np.median(values))  # a laser's range, not the room's
        if lines_at_top >= NO_RETURN_MIN_LINES and at_top >= densest and beyond_most:
            return float(far[far > low].min())
        return fallback

    def _has_static(self) -> bool:
        return self._mount is not None or "/scan_rear" in self._kind_of_topic

    def raw(self, topics: set[str] | None) -> Iterator[RawRecord]:
        for stamp, i, topic, seq in self._records:
            if topics is None or topic in topics:
                line = b"" if i < 0 else self._lines[i]
                yield RawRecord(topic, self.topics[topic].msgtype, stamp, b"%d %s" % (seq, line))

    def deserializer(self) -> Callable[[Any], Any]:
        return self._message

    def close(self) -> None:
        self._lines = []

    # -- messages --------------------------------------------------------------------------------

    def _message(self, rec: Any) -> Any:
        seq_text, _, line = bytes(rec.raw).partition(b" ")
        seq = int(seq_text)
        if rec.topic == "/tf_static":
            return self._static(rec.log_time_ns)
        words = line.split()
        kind, text = words[0].decode("ascii", "replace"), words[1:]
        if rec.topic not in ("/odom", "/tf"):
            return self._scan(_parse_laser(kind, text, self._max_range, self._increment), rec.topic, seq)
        stamp, pose = _parse_odom(text) if kind == "ODOM" else _laser_odometry(kind, text)
        if rec.topic == "/odom":
            return self._odometry(stamp, pose, seq)
        return self._types["tf2_msgs/msg/TFMessage"](transforms=[self._transform(stamp, ODOM_FRAME, BASE_FRAME, pose, seq)])

    def _header(self, stamp_ns: int, frame: str, seq: int) -> Any:
        t = self._types
        return t["std_msgs/msg/Header"](seq=seq, stamp=t["builtin_interfaces/msg/Time"](
            sec=stamp_ns // 1_000_000_000, nanosec=stamp_ns % 1_000_000_000), frame_id=frame)

    def _scan(self, laser: _Laser, topic: str, seq: int) -> Any:
        ranges = laser.ranges.astype(np.float32)
        ranges[ranges >= laser.max_range_m] = np.inf
        n = ranges.size
        return self._types[SCAN_MSGTYPE](
            header=self._header(laser.stamp_ns, _LASERS[topic][1], seq),
            angle_min=laser.start_rad, angle_max=laser.start_rad + (n - 1) * laser.increment_rad,
            angle_increment=laser.increment_rad, time_increment=0.0, scan_time=0.0,
            range_min=0.001, range_max=float(laser.max_range_m), ranges=ranges, intensities=np.zeros(0, np.float32))

    def _pose(self, pose: tuple[float, float, float]) -> Any:
        t = self._types
        x, y, th = pose
        return t["geometry_msgs/msg/Pose"](
            position=t["geometry_msgs/msg/Point"](x=x, y=y, z=0.0),
            orientation=t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=math.sin(th / 2), w=math.cos(th / 2)))

    def _odometry(self, stamp_ns: int, pose: tuple[float, float, float], seq: int) -> Any:
        t = self._types
        zero = t["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)
        return t[ODOM_MSGTYPE](
            header=self._header(stamp_ns, ODOM_FRAME, seq), child_frame_id=BASE_FRAME,
            pose=t["geometry_msgs/msg/PoseWithCovariance"](pose=self._pose(pose), covariance=np.zeros(36)),
            twist=t["geometry_msgs/msg/TwistWithCovariance"](
                twist=t["geometry_msgs/msg/Twist"](linear=zero, angular=zero), covariance=np.zeros(36)))

    def _transform(self, stamp_ns: int, parent: str, child: str, pose: tuple[float, float, float], seq: int) -> Any:
        t = self._types
        p = self._pose(pose)
        return t["geometry_msgs/msg/TransformStamped"](
            header=self._header(stamp_ns, parent, seq), child_frame_id=child,
            transform=t["geometry_msgs/msg/Transform"](
                translation=t["geometry_msgs/msg/Vector3"](x=p.position.x, y=p.position.y, z=0.0), rotation=p.orientation))

    def _static(self, stamp_ns: int) -> Any:
        transforms = []
        if self._mount is not None:
            transforms.append(self._transform(stamp_ns, BASE_FRAME, _LASERS["/scan"][1], self._mount, 0))
        if "/scan_rear" in self._kind_of_topic:
            offset = self.params.get("robot_rearlaser_offset", 0.0)
            transforms.append(self._transform(stamp_ns, BASE_FRAME, _LASERS["/scan_rear"][1], (offset, 0.0, math.pi), 0))
        return self._types[TF_MSGTYPE](transforms=transforms)


def _typestore() -> Any:
    """The ROS 1 message types (with header.seq), tf2_msgs/TFMessage added."""
    store = get_typestore(Stores.ROS1_NOETIC)
    store.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms", TF_MSGTYPE))
    return store


def write_flaser_log(bag_path: str | Path, out_path: str | Path, scan_topic: str = "/scan",
                     odom_topic: str = "/odom") -> int:
    """Write a bag's LaserScans as a CARMEN log of ``FLASER`` lines (the classic benchmarks' own format); the
    number of lines.

    Lines are in recording order (``header.seq`` when the bag has it, else the
    bag's order), each with the odometry pose nearest its stamp (``odom_topic``,
    nav_msgs/Odometry) as both its laser and robot pose, and its stamp to the
    microsecond as ipc and logger timestamps. Readings that are not finite are
    written as :data:`FLASER_MAX_RANGE_M`. The beams' angles are not written (a
    FLASER line has none): read back, they span 180 degrees end to end.
    """
    from bagtools.io.decode import decode_odometry
    from bagtools.io.reader import open_bag

    scans, odom = [], []
    with open_bag(bag_path) as bag:
        for n, rec in enumerate(bag.messages([scan_topic, odom_topic])):
            stamp = rec.msg.header.stamp
            if rec.topic == scan_topic:
                order = getattr(rec.msg.header, "seq", None)
                ranges = np.asarray(rec.msg.ranges, dtype=np.float64)
                ranges = np.where(np.isfinite(ranges), ranges, FLASER_MAX_RANGE_M)
                scans.append((n if order is None else order, f"{stamp.sec}.{stamp.nanosec // 1000:06d}",
                              stamp.sec + stamp.nanosec * 1e-9, ranges))
            else:
                sample = decode_odometry(rec.msg)
                qx, qy, qz, qw = sample.orientation_xyzw
                yaw = math.atan2(2 * (qw * qz + qx * qy), 1 - 2 * (qy * qy + qz * qz))
                odom.append((sample.stamp_ns * 1e-9, (sample.position_m[0], sample.position_m[1], yaw)))
    scans.sort(key=lambda s: s[0])
    odom.sort(key=lambda o: o[0])
    poses = np.array([o[1] for o in odom]).reshape(-1, 3)
    if len(odom):  # the odometry sample nearest each scan's stamp (the earlier one on a tie)
        times = np.array([o[0] for o in odom])
        stamps = np.array([s[2] for s in scans])
        after = np.clip(np.searchsorted(times, stamps), 0, len(times) - 1)
        before = np.maximum(after - 1, 0)
        nearest = np.where(np.abs(stamps - times[before]) <= np.abs(times[after] - stamps), before, after)
    with Path(out_path).open("w") as f:
        for k, (_, text, _, ranges) in enumerate(scans):
            x, y, th = poses[nearest[k]] if len(odom) else (0.0, 0.0, 0.0)
            pose = f"{x:.6f} {y:.6f} {th:.6f}"
            f.write(f"FLASER {len(ranges)} {' '.join(f'{r:.2f}' for r in ranges)} {pose} {pose} {text} nohost {text}\n")
    return len(scans)
