"""The laser scans and point clouds of a bag, decoded, checked and counted: the one dataset reader.

Every command that consumes sensor data (map-cloud, grid, ndt-odom, slam) reads
it here, in bag order, the way KISS-ICP's datasets feed its pipeline:

- :func:`scan_clock` tells whether a topic's header stamps can time its scans
  (:class:`ScanClock`): a log whose stamps are all zero, all equal or mostly
  going backwards says nothing of when its scans were taken; they are then
  taken in logging order, one second apart.
- :class:`ScanStream` yields the LaserScans of one topic as
  :class:`~bagtools.io.LaserScanArrays`, timed by its clock. A scan whose header places no beam
  (non-finite or zero angle_increment) is skipped; with ``increasing`` a scan
  whose stamp is not after the previous one is skipped; with ``min_returns`` a
  scan with fewer valid returns is skipped. Every skip is counted by reason and
  every implausible header value (negative range_min, infinite range_max, an
  increment of the wrong sign) is counted by kind, and :meth:`ScanStream.warnings`
  says both in one line per kind.
- :class:`SensorStream` yields the points of a PointCloud2 or LaserScan topic,
  (N,3) in the sensor frame, with the same counting.
- :func:`posed_scan_chunks` attaches poses from a
  :class:`~bagtools.dataset.poses.ScanPoseSource` to chunks of scans (one
  vectorized lookup per chunk and scan frame).
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, replace
from functools import partial

import numpy as np

from bagtools.dataset.poses import ScanPoseSource
from bagtools.errors import TopicError
from bagtools.io import (
    LASERSCAN_TYPES,
    POINTCLOUD2_TYPES,
    BagReader,
    LaserScanArrays,
    decode_laserscan,
    decode_pointcloud2,
)
from bagtools.io.cdr import laserscan_from_cdr, pointcloud2_from_cdr
from bagtools.io.decode import CloudArrays, DecodeError
from bagtools.io.records import Record
from bagtools.progress import progress

SKIP_BACKWARDS = "stamp not after the previous scan"
CHUNK_SCANS = 256
"""Scans posed per batch lookup."""


#: How far (in scans) a scan may sit from its place in stamp order for header.seq to count as its recording
#: order: a publisher that restarted (seq from 0 again) or two publishers on one topic move scans much farther.
MAX_REORDER_SCANS = 100


def recording_order(stamps_ns: np.ndarray, seqs: list[int | None]) -> np.ndarray | None:
    """The order the scans were recorded in, when their stamps say otherwise; None when the stamps' order holds.

    ``stamps_ns`` (N,) and ``seqs`` (N,): the scans as read (stamp order). ROS 1
    publishers number their messages (``header.seq``) as they send them; when
    every scan has a distinct seq and sorting by it moves no scan more than
    :data:`MAX_REORDER_SCANS` places, a scan whose seq is out of step with its
    stamp was stamped with a time earlier (or later) than its neighbours' (the
    Intel Research Lab log stamps 631 of 13631 scans up to 0.9 s early). Returns
    the permutation of ``range(N)`` in seq order, or None (no seq, a restart, or
    nothing out of order). (Where the seq is the recording order and the stamps
    move a scan farther, :func:`scan_clock` finds the clock unusable.)
    """
    n = len(seqs)
    if n < 2 or any(s is None for s in seqs):
        return None
    seq = np.asarray(seqs, dtype=np.int64)
    order = np.argsort(seq, kind="stable")
    if np.all(order == np.arange(n)) or np.unique(seq).size != n:
        return None
    if np.abs(order - np.arange(n)).max() > MAX_REORDER_SCANS:
        return None
    return order


def stamped_late(stamps_ns: np.ndarray, order: np.ndarray) -> np.ndarray:
    """(N,) bool: the messages stamped before a message recorded before them, ``order`` being the recording
    order (a permutation of the messages as read, e.g. from :func:`recording_order`)."""
    in_order = np.asarray(stamps_ns)[order]
    late = np.zeros(len(in_order), dtype=bool)
    late[order[1:]] = in_order[1:] < np.maximum.accumulate(in_order)[:-1]
    return late


#: A topic's stamps cannot time its scans when more than this share of its steps (bag order) do not move forward
#: (all zero, all equal, or mostly going backwards; a few late ones are skipped as before).
UNUSABLE_STAMPS_SHARE = 0.5
#: Scans whose stamps cannot be used are stamped the first stamp plus this per scan, in logging order (ns).
LOGGING_ORDER_STEP_NS = 1_000_000_000


@dataclass(frozen=True)
class ScanClock:
    """How a topic's scans are timed: by their header stamps (``usable``), or, when those say nothing, by their
    logging order: the ``index``-th message of the topic (bag order, counting every message) is stamped
    ``first_ns + index * LOGGING_ORDER_STEP_NS``, or, when the bag's seq is its recording order (``by_seq``), the
    message of header.seq ``seq`` is stamped ``first_ns + (seq - first_seq) * LOGGING_ORDER_STEP_NS``. ``why``:
    what is wrong with the stamps."""

    usable: bool = True
    first_ns: int = 0
    why: str = ""
    by_seq: bool = False
    first_seq: int = 0

    def stamp_ns(self, index: int, header_ns: int, seq: int | None = None) -> int:
        if self.usable:
            return header_ns
        rank = seq - self.first_seq if self.by_seq and seq is not None else index
        return self.first_ns + rank * LOGGING_ORDER_STEP_NS

    def warning(self, topic: str) -> str | None:
        """The one line that says the stamps were ignored (None when they were used)."""
        if self.usable:
            return None
        return (f"the stamps of {topic} cannot time its scans ({self.why}): they were ignored, the scans taken in "
                f"logging order, {LOGGING_ORDER_STEP_NS / 1e9:g} s apart from the first stamp (the output's stamps "
                "are these)")


def scan_clock(bag: BagReader, topic: str) -> ScanClock:
    """The clock of ``topic``'s scans (see :class:`ScanClock`), from their header stamps in recording order: the
    bag's order, or header.seq's where the bag says that is the recording order (a CARMEN log, whose reader
    orders its lines by stamp: a clock that ran backwards would otherwise look right)."""
    stamps, seqs = [], []
    for rec in bag.messages([topic], from_cdr={topic: laserscan_from_cdr}):
        stamps.append(rec.msg.stamp_ns if isinstance(rec.msg, LaserScanArrays) else _header_ns(rec.msg))
        seqs.append(getattr(getattr(rec.msg, "header", None), "seq", None))
    stamps = np.array(stamps, dtype=np.int64)
    if stamps.size < 3:
        return ScanClock()
    first_seq = 0
    by_seq = bag.seq_is_recording_order and None not in seqs and len(set(seqs)) == len(seqs)
    if by_seq:
        order = np.argsort(np.array(seqs, dtype=np.int64), kind="stable")
        stamps, first_seq = stamps[order], int(seqs[order[0]])
    steps = np.diff(stamps)
    stuck = int(np.count_nonzero(steps <= 0))
    # where the seq is the recording order, a stamp that would move its scan farther than a stamp's jitter does
    # (MAX_REORDER_SCANS) says the clock went back (a restart): it cannot order the log
    went_back = by_seq and int(np.abs(np.argsort(stamps, kind="stable") - np.arange(stamps.size)).max()) > \
        MAX_REORDER_SCANS
    if stuck <= UNUSABLE_STAMPS_SHARE * steps.size and not went_back:
        return ScanClock()
    if np.all(stamps == stamps[0]):
        why = f"every stamp is {stamps[0] / 1e9:.9f} s"
    elif stuck > UNUSABLE_STAMPS_SHARE * steps.size:
        why = f"{stuck} of {steps.size} stamps are not after the one before"
    else:
        late = int(np.count_nonzero(stamps[1:] < np.maximum.accumulate(stamps)[:-1]))
        why = f"the clock went back: {late} of {steps.size} stamps lie before an earlier line's"
    return ScanClock(False, int(stamps[0]), why, by_seq, first_seq)


def _header_ns(msg: object) -> int:
    stamp = msg.header.stamp
    return int(getattr(stamp, "sec", getattr(stamp, "secs", 0))) * 1_000_000_000 + int(
        getattr(stamp, "nanosec", getattr(stamp, "nsecs", 0)))


def require_topic(bag: BagReader, topic: str, msgtypes: tuple[str, ...], what: str) -> None:
    """Raise :class:`TopicError` naming the topics of the wanted types when ``topic`` is missing or of another type."""
    if topic not in bag.topics:
        fits = [t.name for t in bag.topics.values() if t.msgtype in msgtypes]
        hint = f"{what} topics: {', '.join(fits)}; choose one with --topic" if fits else f"the bag has no {what} topic"
        raise TopicError(f"no topic '{topic}' in the bag ({hint})", bag.path)
    bag.require_topic(topic, msgtypes)


@dataclass(frozen=True, slots=True)
class ScanMessage:
    """One usable LaserScan, its bag (log) time in ns and its ROS 1 header ``seq`` (None without one)."""

    log_time_ns: int
    scan: LaserScanArrays
    seq: int | None = None


class ScanStream:
    """The usable LaserScans of ``topic`` in bag order (see the module docstring).

    Args:
        bag: an open bag.
        topic: a sensor_msgs/LaserScan topic (TopicError otherwise).
        clock: how the scans are timed (:func:`scan_clock`; default: by their header stamps).
        increasing: skip scans whose stamp is not after the previous usable one.
        min_returns: skip scans with fewer valid returns than this.
        desc: progress-bar label (None: no bar).
    """

    def __init__(self, bag: BagReader, topic: str, *, clock: ScanClock | None = None, increasing: bool = False,
                 min_returns: int = 0, desc: str | None = "scans") -> None:
        require_topic(bag, topic, LASERSCAN_TYPES, "LaserScan")
        self.bag = bag
        self.topic = topic
        self.clock = clock or ScanClock()
        self.increasing = increasing
        self.min_returns = min_returns
        self.desc = desc
        self.total = bag.topics[topic].count
        self.read = 0
        self.skipped: Counter[str] = Counter()
        self.notes: Counter[str] = Counter()
        self.frame_ids: set[str] = set()
        self._first_backwards_ns: int | None = None
        self._last_ns: int | None = None  # the last usable scan's stamp

    def __iter__(self) -> Iterator[ScanMessage]:
        records = self.bag.messages([self.topic], from_cdr=self.from_cdr)
        if self.desc is not None:
            records = progress(records, total=self.total, desc=self.desc, unit="scan")
        for rec in records:
            item = self.decode(rec)
            if item is not None:
                yield item

    @property
    def from_cdr(self) -> dict[str, Callable[[bytes | memoryview], LaserScanArrays | None]]:
        """The topic's CDR decoder, for :meth:`~bagtools.io.BagReader.messages` (a pass over several topics
        feeds this stream's records to :meth:`decode`)."""
        return {self.topic: laserscan_from_cdr}

    def decode(self, rec: Record) -> ScanMessage | None:
        """One record of the topic as a usable scan, or None when it is skipped (and counted)."""
        index = self.read
        self.read += 1
        try:
            scan = rec.msg if isinstance(rec.msg, LaserScanArrays) else decode_laserscan(rec.msg)
        except DecodeError as err:
            self.skipped[f"unusable header: {err.problem}"] += 1
            return None
        seq = getattr(getattr(rec.msg, "header", None), "seq", None)  # ROS 1 numbers its messages
        if not self.clock.usable:  # each its own stamp in logging order: none is skipped as going backwards
            scan = replace(scan, stamp_ns=self.clock.stamp_ns(index, scan.stamp_ns, seq))
        if scan.notes:
            self.notes.update(scan.notes)
        if self.increasing and self.clock.usable and self._last_ns is not None and scan.stamp_ns <= self._last_ns:
            self.skipped[SKIP_BACKWARDS] += 1
            if self._first_backwards_ns is None:
                self._first_backwards_ns = scan.stamp_ns
            return None
        if self.min_returns and int(np.count_nonzero(scan.valid)) < self.min_returns:
            self.skipped[f"fewer than {self.min_returns} valid ranges"] += 1
            return None
        self.frame_ids.add(scan.frame_id)
        self._last_ns = scan.stamp_ns
        return ScanMessage(rec.log_time_ns, scan, None if seq is None else int(seq))

    def warnings(self) -> list[str]:
        """One line per kind of skipped scan and per kind of implausible header value, with counts."""
        out = [] if self.clock.usable else [self.clock.warning(self.topic)]
        for reason, n in self.skipped.items():
            if reason == SKIP_BACKWARDS:
                out.append(f"{n} scan(s) on {self.topic} skipped: header stamp not after the previous scan's "
                           f"(time going backwards), first at {self._first_backwards_ns / 1e9:.9f} s")
            else:
                out.append(f"{n} scan(s) on {self.topic} skipped: {reason}")
        for note, n in self.notes.items():
            out.append(f"{self.topic}: {note} ({n} scan(s))")
        return out


@dataclass(frozen=True)
class SensorPoints:
    """One message's points: ``points`` (N,3) float32 in ``frame_id`` at header ``stamp_ns``; ``log_time_ns`` is its bag time.

    With attributes asked for, ``intensity`` (N,) float32 and ``rgb`` (N,3) uint8
    are aligned with ``points`` when the sensor gave them (None otherwise);
    ``scan`` is the LaserScan the points come from (None for a PointCloud2).
    """

    stamp_ns: int
    log_time_ns: int
    frame_id: str
    points: np.ndarray
    intensity: np.ndarray | None = None
    rgb: np.ndarray | None = None
    scan: LaserScanArrays | None = None


class SensorStream:
    """The points of every PointCloud2 or LaserScan message on ``topic``, in bag order.

    A LaserScan gives its valid returns at z = 0 of the scan frame (through a
    :class:`ScanStream`); a PointCloud2 its finite, plausible points. Messages
    that cannot be decoded are skipped and counted; :meth:`warnings` says so.
    With ``attributes``, each message's intensities (a LaserScan's, when it has
    one per beam) and colours come along (see :func:`~bagtools.io.decode_pointcloud2`).
    """

    def __init__(self, bag: BagReader, topic: str, desc: str | None = "mapping", attributes: bool = False) -> None:
        require_topic(bag, topic, POINTCLOUD2_TYPES + LASERSCAN_TYPES, "PointCloud2 or LaserScan")
        self.bag = bag
        self.topic = topic
        self.desc = desc
        self.attributes = attributes
        self.is_scan = bag.topics[topic].msgtype in LASERSCAN_TYPES
        self.scans = ScanStream(bag, topic, desc=desc) if self.is_scan else None
        self.total = bag.topics[topic].count
        self.skipped: Counter[str] = Counter()
        self.notes: Counter[str] = Counter()
        self.implausible_points = 0

    def __iter__(self) -> Iterator[SensorPoints]:
        records: Iterable = self.bag.messages([self.topic], from_cdr=self.from_cdr)
        if self.desc is not None:
            records = progress(records, total=self.total, desc=self.desc, unit="scan" if self.is_scan else "cloud")
        for rec in records:
            item = self.decode(rec)
            if item is not None:
                yield item

    @property
    def from_cdr(self) -> dict[str, Callable[[bytes | memoryview], object]]:
        """The topic's CDR decoder, for :meth:`~bagtools.io.BagReader.messages` (a pass over several topics
        feeds this stream's records to :meth:`decode`)."""
        if self.scans is not None:
            return self.scans.from_cdr
        return {self.topic: partial(pointcloud2_from_cdr, attributes=self.attributes)}

    def decode(self, rec: Record) -> SensorPoints | None:
        """One record of the topic as points, or None when it is skipped (and counted)."""
        if self.scans is not None:
            item = self.scans.decode(rec)
            if item is None:
                return None
            scan = item.scan
            xy = scan.points_xy()
            points = np.zeros((xy.shape[0], 3), dtype=np.float32)
            points[:, :2] = xy
            intensity = None
            if self.attributes and scan.intensities.size == scan.ranges_m.size and scan.ranges_m.size:
                intensity = np.asarray(scan.intensities[scan.valid], dtype=np.float32)
            return SensorPoints(scan.stamp_ns, item.log_time_ns, scan.frame_id, points, intensity,
                                scan=scan if self.attributes else None)
        try:
            cloud = rec.msg if isinstance(rec.msg, CloudArrays) else decode_pointcloud2(rec.msg, attributes=self.attributes)
        except DecodeError as err:
            self.skipped[f"undecodable cloud: {err.problem}"] += 1
            return None
        self.implausible_points += cloud.n_implausible
        self.notes.update(cloud.notes)
        return SensorPoints(cloud.stamp_ns, rec.log_time_ns, cloud.frame_id, cloud.points, cloud.intensity, cloud.rgb)

    @property
    def skip_counts(self) -> Counter[str]:
        return self.scans.skipped if self.scans is not None else self.skipped

    def warnings(self) -> list[str]:
        """One line per kind of skipped message or dropped point, with counts."""
        if self.scans is not None:
            return self.scans.warnings()
        out = [f"{n} cloud(s) on {self.topic} skipped: {reason}" for reason, n in self.skipped.items()]
        out += [f"{self.topic}: {note} ({n} cloud(s))" for note, n in self.notes.items()]
        if self.implausible_points:
            out.append(f"{self.implausible_points} point(s) on {self.topic} dropped: a coordinate beyond "
                       "1e5 m (damaged data, or is_bigendian set wrong)")
        return out


@dataclass(frozen=True)
class PosedScan:
    """One scan and where it was taken.

    ``T_frame_scan`` (4,4) is the scan frame's pose in the map's frame (NaN when
    unknown); ``skip_reason`` is '' when the pose is known, else why not.
    """

    scan: LaserScanArrays
    T_frame_scan: np.ndarray
    skip_reason: str


def _pose_chunk(scans: list[LaserScanArrays], poses: ScanPoseSource) -> list[PosedScan]:
    stamps = np.array([s.stamp_ns for s in scans], dtype=np.int64)
    frames = np.array([s.frame_id for s in scans], dtype=object)
    T = np.empty((len(scans), 4, 4))
    reasons = np.empty(len(scans), dtype=object)
    for frame_id in dict.fromkeys(frames):
        rows = np.flatnonzero(frames == frame_id)
        T[rows], reasons[rows] = poses.lookup(str(frame_id), stamps[rows])
    return [PosedScan(scan, T[i], str(reasons[i])) for i, scan in enumerate(scans)]


def posed_scan_chunks(scans: ScanStream, poses: ScanPoseSource, chunk_scans: int = CHUNK_SCANS) -> Iterator[list[PosedScan]]:
    """Yield the scans of ``scans`` with their poses, in bag order, ``chunk_scans`` at a time."""
    chunk: list[LaserScanArrays] = []
    for item in scans:
        chunk.append(item.scan)
        if len(chunk) == chunk_scans:
            yield _pose_chunk(chunk, poses)
            chunk = []
    if chunk:
        yield _pose_chunk(chunk, poses)
