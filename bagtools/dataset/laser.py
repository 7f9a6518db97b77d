"""A bag's laser scans as a front end takes them: :class:`LaserDataset` reads, repairs and checks, a front end
registers (the KISS-ICP split: a dataset feeding one small algorithm object).

    LaserDataset(topic, min_points=...).read(bag) -> ScanInputs
        _load_odometry()   tf and /odom: the odometry frame, the robot base frame (repaired samples)
        _read_scans()      every usable scan's valid points (ScanStream counts the rest)
        _scan_offset()     T_base_scan: the given offset, else tf, else identity with a warning
        _order()           recording order (header.seq) when the stamps disagree with it
        _odometry_at()     the odometry at the scans' stamps (none when the stamps say nothing)

Frames: the points are in the scan frame; :meth:`ScanInputs.points_base` moves them by ``T_base_scan`` into the
robot base frame; the odometry is T_odom_base. Every repair and skip is counted on the dataset and said once in
its ``warnings``.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field

import numpy as np

from bagtools.dataset.scans import ScanClock, ScanStream, recording_order, require_topic, scan_clock, stamped_late
from bagtools.errors import BagtoolsError
from bagtools.io import (
    LASERSCAN_TYPES, ODOMETRY_TYPES, BagReader, LaserScanArrays, TfArrays, TfCollector, decode_odometry,
)
from bagtools.io.cdr import odometry_from_cdr
from bagtools.io.decode import OdometrySample
from bagtools.tf import TfBuffer, TransformException
from bagtools.tf.repair import NO_SCAN_TRANSFORM_WARNING, repair_dynamic_tf
from bagtools.transforms import pose2tform

#: Returns farther than this are not read (m): no 2D laser places the robot better by them than by its near
#: returns, and a search's rasters are sized by the farthest point (500 m returns needed 100 M cells).
MATCH_MAX_RANGE_M = 100.0
#: Repeated (frozen) scans are warned about when the odometry moves more than this meanwhile (m).
FROZEN_SCANS_MOVED_M = 0.5
ODOM_TOPIC = "/odom"


@dataclass
class ScanInputs:
    """The scans of a bag as the front end takes them.

    ``stamps_ns`` (N,) int64 header stamps of the usable scans, in stamp order;
    ``points`` their valid returns (M_k, 2) in the scan frame (m); ``order`` the
    order to register them in (their recording order, :meth:`LaserDataset._order`);
    ``odometry`` (T_odom_base (N, 4, 4), valid (N,)) at the stamps, None without
    odometry; ``T_base_scan`` (4, 4) the laser's mount on the robot base; ``clock``
    how the scans are timed (their stamps, or their logging order when those say nothing).
    """

    stamps_ns: np.ndarray
    points: list[np.ndarray]
    order: np.ndarray
    odometry: tuple[np.ndarray, np.ndarray] | None
    T_base_scan: np.ndarray
    clock: ScanClock = field(default_factory=ScanClock)

    def points_base(self, k: int) -> np.ndarray:
        """Scan ``k``'s points (M, 2) in the robot base frame (m)."""
        R, t = self.T_base_scan[:2, :2], self.T_base_scan[:2, 3]
        return self.points[k] @ R.T + t


class LaserDataset:
    """The scans of one LaserScan ``topic`` of a bag, with the wheel odometry and the laser's mount (see the
    module docstring).

    ``min_points``: a scan with fewer valid returns (within MATCH_MAX_RANGE_M) is skipped and counted (the
    matcher's minimum); ``use_odometry``: read /odom and tf's odom -> base; ``scan_frame_offset``: the laser's
    pose on the base [x, y, yaw] (m, m, rad) when given, instead of tf's; ``keep_scans``: keep each usable scan's
    LaserScan (``scans``, for results.mcap).
    """

    def __init__(self, topic: str, min_points: int, use_odometry: bool = True,
                 scan_frame_offset: tuple[float, float, float] | None = None, keep_scans: bool = False) -> None:
        self.topic = topic
        self.min_points = min_points
        self.use_odometry = use_odometry
        self.scan_frame_offset = scan_frame_offset
        self.keep_scans = keep_scans
        self.scans: list[LaserScanArrays] = []
        self.skipped: dict[str, int] = {}
        self.warnings: list[str] = []
        self.buffer: TfBuffer | None = None
        self.odom_frame = "odom"
        self.base_frame: str | None = None
        self.odometry_source: str | None = None
        self.T_base_scan = np.eye(4)
        self.scan_frame = ""
        self.seqs: list[int | None] = []
        self.reordered = 0
        self.repeated = 0
        self.stamps_ignored: str | None = None  # why the scans' stamps were ignored (logging order instead)

    def read(self, bag: BagReader) -> ScanInputs:
        """What the front end is fed, read from the open ``bag``: the usable scans, the order to register them in,
        the odometry at their stamps, the laser's mount (see :class:`ScanInputs`). Frames, counts and warnings
        are set on the dataset on the way."""
        require_topic(bag, self.topic, LASERSCAN_TYPES, "LaserScan")
        self._load_odometry(bag)
        clock = scan_clock(bag, self.topic)
        self.stamps_ignored = None if clock.usable else clock.why
        stamps, points = self._read_scans(bag, clock)
        self.warnings[:0] = list(bag.warnings)
        self._scan_offset(stamps)
        if len(stamps) == 0:
            return ScanInputs(stamps, points, np.zeros(0, dtype=np.intp), None, self.T_base_scan, clock)
        order = self._order(stamps)
        odometry = None
        if clock.usable:
            odometry = self._odometry_at(stamps, out_of_order=stamped_late(stamps, order))
        elif self.has_odometry:
            self.warnings.append("the odometry is not used: without the scans' stamps nothing ties it to them")
            self.odometry_source = None
        return ScanInputs(stamps, points, order, odometry, self.T_base_scan, clock)

    @property
    def has_odometry(self) -> bool:
        """Whether wheel odometry was found (and is used)."""
        return self.odometry_source is not None

    def no_scan_problem(self, bag: BagReader) -> str:
        """Why there is no usable scan in ``bag``, in words (after :meth:`read` found none)."""
        return (f"no usable scan on {self.topic}: every scan was skipped "
                f"({', '.join(f'{n} {r}' for r, n in self.skipped.items()) or 'none recorded'})"
                f"{bag.decode_note(self.topic)}")

    def odometry_frame_parent(self) -> str | None:
        """The parent of the odometry frame in the bag's tf (a localizer's map above odom), or None (a root, no
        tf)."""
        if self.buffer is None or not self.buffer.has_frame(self.odom_frame):
            return None
        return self.buffer.parent(self.odom_frame)

    def check_frozen(self, inputs: ScanInputs) -> None:
        """Count scans that repeat the scan before them (in recording order) exactly (``repeated``), and warn when
        the odometry moved meanwhile.

        A real laser's ranges are never bit-identical twice (noise); a driver that froze sends its last scan
        again, and scan matching then says the robot stood still."""
        points, order, odometry = inputs.points, inputs.order, inputs.odometry
        same = np.zeros(len(order), dtype=bool)
        for k in range(1, len(order)):
            a, b = points[order[k - 1]], points[order[k]]
            same[k] = a.shape == b.shape and bool(np.array_equal(a, b))
        self.repeated = int(same.sum())
        if not self.repeated or odometry is None:
            return
        xy = odometry[0][order][:, :2, 3]
        moved_m = float(np.hypot(*(xy[1:] - xy[:-1]).T)[same[1:]].sum())
        if moved_m > FROZEN_SCANS_MOVED_M:
            self.warnings.append(f"{self.repeated} scan(s) on {self.topic} repeat the scan before them exactly "
                                 f"while the odometry moves {moved_m:.2f} m (a frozen laser driver?): their matches "
                                 "say the robot stood still there")

    # -- steps of read() ---------------------------------------------------------------------------

    def _load_odometry(self, bag: BagReader) -> None:
        """Build the tf buffer (with /odom added when tf lacks it) and pick the odometry and base frames."""
        collector = TfCollector()
        collector.check(bag)
        odom_samples = []
        odom_seqs: list[int | None] = []
        has_odom_topic = (self.use_odometry and ODOM_TOPIC in bag.topics
                          and bag.topics[ODOM_TOPIC].msgtype in ODOMETRY_TYPES)
        topics = [t for t in collector.topics if t in bag.topics] + ([ODOM_TOPIC] if has_odom_topic else [])
        # tf and /odom stored as CDR are decoded straight from their bytes (a deserialized message otherwise)
        for rec in bag.messages(topics, from_cdr={**collector.from_cdr, ODOM_TOPIC: odometry_from_cdr}):
            if rec.topic == ODOM_TOPIC:
                decoded = isinstance(rec.msg, OdometrySample)
                odom_samples.append(rec.msg if decoded else decode_odometry(rec.msg))
                odom_seqs.append(None if decoded else getattr(rec.msg.header, "seq", None))
            else:
                collector.add(rec)
        dynamic, static = collector.arrays()
        late_ns = self._late_odometry(odom_samples, odom_seqs)
        parents = np.array([p.lstrip("/") for p in dynamic.parent], dtype=object)
        children = np.array([c.lstrip("/") for c in dynamic.child], dtype=object)
        if odom_samples:
            self.odom_frame = odom_samples[0].frame_id.lstrip("/") or "odom"
            self.base_frame = odom_samples[0].child_frame_id.lstrip("/") or None
        if self.base_frame is None:
            below_odom = sorted(set(children[parents == self.odom_frame]))
            self.base_frame = below_odom[0] if below_odom else None
        if self.base_frame is not None and self.use_odometry:
            edge = (parents == self.odom_frame) & (children == self.base_frame)
            if edge.any():
                self.odometry_source = f"/tf {self.odom_frame} -> {self.base_frame}"
                if late_ns.size:  # /odom's seq says which of the edge's samples are stamped out of order
                    dynamic = dynamic.select(~(edge & np.isin(dynamic.stamp_ns, late_ns)))
                dynamic = repair_dynamic_tf(dynamic, self.warnings)[0]
            elif odom_samples:
                odom_samples = [s for s in odom_samples if s.stamp_ns not in set(late_ns.tolist())]
                n = len(odom_samples)
                dynamic = TfArrays.concatenate([dynamic, TfArrays(
                    np.full(n, self.odom_frame, dtype=object), np.full(n, self.base_frame, dtype=object),
                    np.array([s.stamp_ns for s in odom_samples], dtype=np.int64),
                    np.array([s.position_m for s in odom_samples]), np.array([s.orientation_xyzw for s in odom_samples]))])
                self.odometry_source = f"{ODOM_TOPIC} ({self.odom_frame} -> {self.base_frame})"
                dynamic = repair_dynamic_tf(dynamic, self.warnings)[0]
        try:
            self.buffer = TfBuffer.from_arrays(dynamic, static, skip_invalid=True)
            self.warnings.extend(self.buffer.warnings)
        except BagtoolsError as err:
            raise BagtoolsError(f"the bag's tf data cannot be used: {err.problem}", bag.path) from err

    def _read_scans(self, bag: BagReader, clock: ScanClock) -> tuple[np.ndarray, list[np.ndarray]]:
        """Stamps (N,) int64 (by ``clock``) and valid points (M_k,2) of the usable scans, in bag order (in logging
        order when the clock is not usable)."""
        stamps: list[int] = []
        points: list[np.ndarray] = []
        seqs: list[int | None] = []
        stream = ScanStream(bag, self.topic, clock=clock, increasing=True, min_returns=self.min_points,
                            desc="reading scans")
        far = Counter()
        for item in stream:
            xy = item.scan.points_xy()
            near = xy[np.einsum("ij,ij->i", xy, xy) <= MATCH_MAX_RANGE_M**2]
            if len(near) < self.min_points:
                far[f"fewer than {self.min_points} returns within {MATCH_MAX_RANGE_M:g} m"] += 1
                continue
            if not self.scan_frame:
                self.scan_frame = item.scan.frame_id.lstrip("/")
            stamps.append(item.scan.stamp_ns)
            seqs.append(item.seq)
            points.append(near)
            if self.keep_scans:
                self.scans.append(item.scan)
        self.skipped = dict(stream.skipped) | dict(far)
        self.warnings.extend(f"{n} scan(s) on {self.topic} skipped: {why}" for why, n in far.items())
        self.warnings.extend(stream.warnings())
        if not clock.usable:  # stamped in logging order, which may not be the bag's (a CARMEN log's lines): sorted
            order = np.argsort(np.asarray(stamps, dtype=np.int64), kind="stable")
            stamps, points, seqs = [stamps[k] for k in order], [points[k] for k in order], [seqs[k] for k in order]
            self.scans = [self.scans[k] for k in order] if self.keep_scans else self.scans
        self.seqs = seqs
        return np.asarray(stamps, dtype=np.int64), points

    def _order(self, stamps: np.ndarray) -> np.ndarray:
        """The order to register the scans in: their recording order (:func:`~bagtools.dataset.recording_order`)
        when their stamps disagree with it, else the order read."""
        order = recording_order(stamps, self.seqs)
        if order is None:
            return np.arange(len(stamps))
        moved = int(np.count_nonzero(np.diff(stamps[order]) < 0))  # scans stamped before the one recorded before them
        self.warnings.append(f"{moved} scan(s) on {self.topic} are stamped before the scan recorded before "
                             "them (header.seq): registered in recording order, each posed at its own stamp, "
                             "with no odometry guess")
        self.reordered = moved
        return order

    def _scan_offset(self, stamps: np.ndarray) -> None:
        """T_base_scan: from the given offset, else tf, else identity with a warning."""
        if self.scan_frame_offset is not None:
            self.T_base_scan = pose2tform(np.asarray(self.scan_frame_offset, dtype=np.float64))
            return
        if self.base_frame is None and self.scan_frame and self.buffer is not None:
            self.base_frame = self._static_root(self.scan_frame)
        if self.base_frame is None or self.base_frame == self.scan_frame or not self.scan_frame:
            return
        if self.buffer is None:
            return
        when = int(stamps[0]) if len(stamps) else None
        for stamp in (when, None):
            try:
                self.T_base_scan = self.buffer.lookup(self.base_frame, self.scan_frame, stamp)
                return
            except TransformException:
                continue
        self.warnings.append(NO_SCAN_TRANSFORM_WARNING.format(base=self.base_frame, scan_frame=self.scan_frame)
                             + " (give --scan-frame-offset X,Y,YAW to set it)")

    def _static_root(self, frame: str) -> str | None:
        """The robot frame a sensor frame is mounted on: the top of its chain of static parents (``base_link``
        for ``laser`` when /tf_static gives base_link -> laser), or None when it has no static parent."""
        root = None
        while self.buffer.has_frame(frame) and self.buffer.is_static(frame):
            parent = self.buffer.parent(frame)
            if parent is None or parent == root:
                break
            root = frame = parent
        return root

    def _late_odometry(self, samples: list, seqs: list[int | None]) -> np.ndarray:
        """Stamps (ns) of the odometry samples stamped before a sample recorded before them (by /odom's
        header.seq): in stamp order they would put the robot back and forth, so they are not used."""
        if not samples:
            return np.zeros(0, dtype=np.int64)
        stamps = np.array([s.stamp_ns for s in samples], dtype=np.int64)
        order = recording_order(stamps, seqs)
        if order is None:
            return np.zeros(0, dtype=np.int64)
        late = stamps[stamped_late(stamps, order)]
        self.warnings.append(f"{late.size} odometry sample(s) on {ODOM_TOPIC} are stamped before a sample recorded "
                             "before them (header.seq): not used")
        return late

    def _odometry_at(self, stamps: np.ndarray, out_of_order: np.ndarray | None = None
                     ) -> tuple[np.ndarray, np.ndarray] | None:
        """(T_odom_base (N,4,4), valid (N,)) at the scan stamps; stamps outside the data take the nearest end.

        A scan stamped out of its recording order (``out_of_order``) had its odometry stamped the same way:
        the stream interpolated at its stamp belongs to another time, so it takes no odometry guess."""
        if not self.has_odometry or self.buffer is None or self.base_frame is None:
            return None
        first, last = self.buffer.frame_time_range(self.base_frame) or (int(stamps[0]), int(stamps[-1]))
        valid = (stamps >= first) & (stamps <= last)
        T, ok = self.buffer.lookup(self.odom_frame, self.base_frame, np.clip(stamps, first, last), return_mask=True)
        if not ok.all():
            # The odometry frame's tree changes over time in odd bags; keep what is valid and hold the rest.
            good = np.flatnonzero(ok)
            if good.size == 0:
                self.warnings.append(f"odometry {self.odom_frame} -> {self.base_frame} cannot be looked up at any scan stamp")
                self.odometry_source = None
                return None
            nearest = good[np.clip(np.searchsorted(good, np.arange(len(ok))), 0, good.size - 1)]
            T = T[nearest]
        valid &= ok
        if not valid.all():
            self.warnings.append(f"{int((~valid).sum())} scan(s) lie outside the odometry's time range: "
                                 "their guesses use constant velocity")
        if out_of_order is not None:
            valid &= ~out_of_order  # said with the recording order (see _order)
        return T, valid


__all__ = ["FROZEN_SCANS_MOVED_M", "MATCH_MAX_RANGE_M", "ODOM_TOPIC", "LaserDataset", "ScanInputs"]
