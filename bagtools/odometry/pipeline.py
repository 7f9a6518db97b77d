"""Laser odometry by 2D NDT scan matching: the robot's trajectory from a bag's LaserScans.

    NdtOdomPipeline(bag, options).run()
        _load_odometry()   tf and /odom: the odometry frame, the robot base frame (repaired samples)
        _read_scans()      every usable scan's valid points (the shared dataset reader counts the rest)
        _scan_offset()     T_base_scan: --scan-frame-offset, else tf, else identity with a warning
        _register()        the scans in order through LaserOdometry (bagtools.odometry.frontend): guesses,
                           gating, grid search when a guess cannot be trusted, NDT refinement, checks
        _evaluate()        /ground_truth of the bag (simulated, or a reference trajectory), APE and RPE

Frames: the front end works in the robot base frame (scan points moved by
T_base_scan); poses are T_odom_base, starting at the odometry pose of the
first scan (identity when the bag has no odometry). The summary counts the
pairs that needed a search, fell back to their guess, contradicted the
odometry, or moved faster than the robot can; warnings say each kind once.
"""

from __future__ import annotations

import time
from collections import Counter
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from bagtools.dataset import ScanClock, ScanStream, recording_order, require_topic, scan_clock, stamped_late
from bagtools.errors import BagtoolsError
from bagtools.io import (
    LASERSCAN_TYPES, ODOMETRY_TYPES, BagReader, LaserScanArrays, TfArrays, TfCollector, decode_odometry, open_bag,
)
from bagtools.io.cdr import odometry_from_cdr
from bagtools.io.decode import OdometrySample
from bagtools.odometry.frontend import LaserOdometry
from bagtools.odometry.options import NdtOdomOptions, cell_size_for
from bagtools.odometry.steps import FrontEndRun
from bagtools.scan_matching import MIN_SCAN_POINTS
from bagtools.progress import progress
from bagtools.simtruth import read_ground_truth
from bagtools.tf import TfBuffer, TransformException
from bagtools.tf.repair import NO_SCAN_TRANSFORM_WARNING, repair_dynamic_tf
from bagtools.trajectory import Trajectory
from bagtools.trajectory.evaluate import odometry_errors
from bagtools.transforms import pose2tform, quat2xyzw, tform2pose, tform2quat

#: Returns farther than this are not matched (m): no 2D laser places the robot better by them than by its near
#: returns, and the search's rasters are sized by the farthest point (500 m returns needed 100 M cells).
MATCH_MAX_RANGE_M = 100.0
#: Repeated (frozen) scans are warned about when the odometry moves more than this meanwhile (m).
FROZEN_SCANS_MOVED_M = 0.5
ODOM_TOPIC = "/odom"


@dataclass
class NdtOdomResult:
    """Trajectories (base frame in the odometry frame) and what the writer needs.

    ``trajectory``: laser odometry; ``odometry``: wheel odometry at the same
    stamps (None without odometry); ``ground_truth``: the bag's /ground_truth in
    the odometry frame (None when absent); ``front_end``: every registered scan
    (points in the base frame, keyframes, matches and covariances: what slam
    builds its graph from); ``problem``: set when nothing could be matched (the
    CLI then exits 2 and writes nothing). ``scans``: the LaserScan of each step,
    as decoded (kept only when asked for: results.mcap re-publishes them);
    ``T_base_scan`` (4,4): the laser mount the points were moved by.
    """

    trajectory: Trajectory | None
    odometry: Trajectory | None
    ground_truth: Trajectory | None
    front_end: FrontEndRun
    summary: dict = field(default_factory=dict)
    problem: str | None = None
    scans: list[LaserScanArrays] = field(default_factory=list)
    T_base_scan: np.ndarray = field(default_factory=lambda: np.eye(4))
    clock: ScanClock = field(default_factory=ScanClock)

    @property
    def scan_points(self) -> list[np.ndarray]:
        """Each used scan's valid points (M,2) in the base frame."""
        return [s.points_base for s in self.front_end.steps]

    @property
    def scan_poses(self) -> np.ndarray:
        """T_odom_base (N,4,4) of each used scan."""
        return self.trajectory.poses if self.trajectory is not None else np.zeros((0, 4, 4))


@dataclass
class ScanInputs:
    """The scans of a bag as the front end takes them.

    ``stamps_ns`` (N,) int64 header stamps of the usable scans, in stamp order;
    ``points`` their valid returns (M_k, 2) in the scan frame (m); ``order`` the
    order to register them in (their recording order, :meth:`NdtOdomPipeline._order`);
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


class NdtOdomPipeline:
    """Laser odometry of one bag (see the module docstring)."""

    def __init__(self, bag_path: str | Path, options: NdtOdomOptions, keep_scans: bool = False) -> None:
        """``keep_scans``: keep each step's LaserScan (``NdtOdomResult.scans``, for results.mcap)."""
        self.bag_path = Path(bag_path)
        self.options = options
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
        self.cell_size_m: float | None = None
        self.seqs: list[int | None] = []
        self.reordered = 0
        self.repeated = 0
        self.stamps_ignored: str | None = None  # why the scans' stamps were ignored (logging order instead)

    def read_inputs(self, bag: BagReader) -> ScanInputs:
        """What the front end is fed, read from the open ``bag``, nothing matched: the usable scans, the
        order to register them in, the odometry at their stamps, the laser's mount (see :class:`ScanInputs`).
        The pipeline's frames, counts and warnings are set on the way."""
        self._require_scan_topic(bag)
        self._load_odometry(bag)
        clock = scan_clock(bag, self.options.topic)
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
        elif self._has_odometry():
            self.warnings.append("the odometry is not used: without the scans' stamps nothing ties it to them")
            self.odometry_source = None
        return ScanInputs(stamps, points, order, odometry, self.T_base_scan, clock)

    def register(self, inputs: ScanInputs) -> tuple[LaserOdometry, np.ndarray]:
        """The laser odometry of :meth:`read_inputs`' scans: the front end, and the base's poses (N, 3)
        [x, y, theta] in the odometry frame at the scans' stamps (stamp order; registered in recording order)."""
        order, odometry = inputs.order, inputs.odometry
        front = self._register(inputs.stamps_ns[order], [inputs.points[i] for i in order],
                               None if odometry is None else (odometry[0][order], odometry[1][order]))
        poses = np.empty((len(inputs.stamps_ns), 3))
        poses[order] = front.run.poses()  # the steps in recording order, the trajectory in stamp order
        return front, poses

    def no_scan_problem(self, bag: BagReader) -> str:
        """Why there is no usable scan in ``bag``, in words (after :meth:`read_inputs` found none)."""
        return (f"no usable scan on {self.options.topic}: every scan was skipped "
                f"({', '.join(f'{n} {r}' for r, n in self.skipped.items()) or 'none recorded'})"
                f"{bag.decode_note(self.options.topic)}")

    def run(self) -> NdtOdomResult:
        with open_bag(self.bag_path) as bag:
            inputs = self.read_inputs(bag)
            stamps, points = inputs.stamps_ns, inputs.points
            if self.options.init == "odom" and not self._has_odometry():
                raise BagtoolsError(f"--init odom needs wheel odometry, but the bag has no {ODOM_TOPIC} and no "
                                    f"'{self.odom_frame}' frame with a child in /tf (use --init auto)", self.bag_path)
            if len(stamps) == 0:
                return NdtOdomResult(None, None, None, FrontEndRun(), self._summary(None, 0.0), self.no_scan_problem(bag))
            order, odometry = inputs.order, inputs.odometry
            t0 = time.perf_counter()
            front, poses = self.register(inputs)
            elapsed_s = time.perf_counter() - t0
            trajectory = Trajectory(stamps, pose2tform(poses))
            odom_traj = None if odometry is None else Trajectory(stamps, odometry[0])
            self._check_frozen(points, order, odometry)
            self.warnings.extend(front.warnings(self.options.topic))
            if len(stamps) == 1:
                self.warnings.append(f"only one usable scan on {self.options.topic}: the trajectory is its one pose, "
                                     "nothing was matched")
            summary = self._summary(front, elapsed_s)
            truth, evaluation = self._evaluate(bag, trajectory, odom_traj)
            summary.update(evaluation)
            summary["warnings"] = self.warnings
        front.run.warnings = list(self.warnings)
        return NdtOdomResult(trajectory, odom_traj, truth, front.run, summary, scans=self.scans,
                             T_base_scan=self.T_base_scan, clock=inputs.clock)

    # -- steps -------------------------------------------------------------------

    def _require_scan_topic(self, bag: BagReader) -> None:
        require_topic(bag, self.options.topic, LASERSCAN_TYPES, "LaserScan")

    def _load_odometry(self, bag: BagReader) -> None:
        """Build the tf buffer (with /odom added when tf lacks it) and pick the odometry and base frames."""
        collector = TfCollector()
        collector.check(bag)
        odom_samples = []
        odom_seqs: list[int | None] = []
        has_odom_topic = (self.options.use_odometry and ODOM_TOPIC in bag.topics
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
        if self.base_frame is not None and self.options.use_odometry:
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
        """Stamps (N,) int64 (by ``clock``) and valid points (M_k,2) of the usable scans, in bag order."""
        stamps: list[int] = []
        points: list[np.ndarray] = []
        seqs: list[int | None] = []
        stream = ScanStream(bag, self.options.topic, clock=clock, increasing=True, min_returns=MIN_SCAN_POINTS,
                            desc="reading scans")
        far = Counter()
        for item in stream:
            xy = item.scan.points_xy()
            near = xy[np.einsum("ij,ij->i", xy, xy) <= MATCH_MAX_RANGE_M**2]
            if len(near) < MIN_SCAN_POINTS:
                far[f"fewer than {MIN_SCAN_POINTS} returns within {MATCH_MAX_RANGE_M:g} m"] += 1
                continue
            if not self.scan_frame:
                self.scan_frame = item.scan.frame_id.lstrip("/")
            stamps.append(item.scan.stamp_ns)
            seqs.append(item.seq)
            points.append(near)
            if self.keep_scans:
                self.scans.append(item.scan)
        self.skipped = dict(stream.skipped) | dict(far)
        self.warnings.extend(f"{n} scan(s) on {self.options.topic} skipped: {why}" for why, n in far.items())
        self.warnings.extend(stream.warnings())
        self.seqs = seqs
        return np.asarray(stamps, dtype=np.int64), points

    def _order(self, stamps: np.ndarray) -> np.ndarray:
        """The order to register the scans in: their recording order (:func:`~bagtools.dataset.recording_order`)
        when their stamps disagree with it, else the order read."""
        order = recording_order(stamps, self.seqs)
        if order is None:
            return np.arange(len(stamps))
        moved = int(np.count_nonzero(np.diff(stamps[order]) < 0))  # scans stamped before the one recorded before them
        self.warnings.append(f"{moved} scan(s) on {self.options.topic} are stamped before the scan recorded before "
                             "them (header.seq): registered in recording order, each posed at its own stamp, "
                             "with no odometry guess")
        self.reordered = moved
        return order

    def _scan_offset(self, stamps: np.ndarray) -> None:
        """T_base_scan: from --scan-frame-offset, else tf, else identity with a warning."""
        if self.options.scan_frame_offset is not None:
            self.T_base_scan = pose2tform(np.asarray(self.options.scan_frame_offset, dtype=np.float64))
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

    def odometry_frame_parent(self) -> str | None:
        """The parent of the odometry frame in the bag's tf (a localizer's map above odom), or None (a root, no
        tf)."""
        if self.buffer is None or not self.buffer.has_frame(self.odom_frame):
            return None
        return self.buffer.parent(self.odom_frame)

    def _has_odometry(self) -> bool:
        return self.odometry_source is not None

    def _check_frozen(self, points: list[np.ndarray], order: np.ndarray,
                      odometry: tuple[np.ndarray, np.ndarray] | None) -> None:
        """Count scans that repeat the scan before them exactly, and warn when the odometry moved meanwhile.

        A real laser's ranges are never bit-identical twice (noise); a driver that froze sends its last scan
        again, and scan matching then says the robot stood still (``scans_repeated`` in the summary)."""
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
            self.warnings.append(f"{self.repeated} scan(s) on {self.options.topic} repeat the scan before them exactly "
                                 f"while the odometry moves {moved_m:.2f} m (a frozen laser driver?): their matches "
                                 "say the robot stood still there")

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
        if not self._has_odometry() or self.buffer is None or self.base_frame is None:
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

    def _register(self, stamps: np.ndarray, points: list[np.ndarray], odometry) -> LaserOdometry:
        """Every scan through the front end, points in the base frame, with the odometry pose when trusted."""
        self.cell_size_m = cell_size_for(points)
        front = LaserOdometry(self.options.front_end(self.cell_size_m))
        R, t = self.T_base_scan[:2, :2], self.T_base_scan[:2, 3]
        odom_xyt = None if odometry is None else np.where(odometry[1][:, None], tform2pose(odometry[0]), np.nan)
        for k in progress(range(len(stamps)), total=len(stamps), desc="matching", unit="scan"):
            odom = None if odom_xyt is None or not np.isfinite(odom_xyt[k]).all() else odom_xyt[k]
            front.register(int(stamps[k]), points[k] @ R.T + t, odom)
        return front

    def _evaluate(self, bag: BagReader, trajectory: Trajectory, odometry: Trajectory | None) -> tuple[Trajectory | None, dict]:
        """Ground truth in the odometry frame, anchored at the first scan, and the errors of NDT and odometry."""
        truth = read_ground_truth(bag, warnings=self.warnings)
        if truth is None:
            return None, {}
        stamps_gt, T_map_gt, gt_child = truth
        gt_child = gt_child.lstrip("/")
        if self.buffer is None:
            return None, {}
        base = self.base_frame or self.scan_frame
        if gt_child == base:
            T_gt_base = np.eye(4)
        elif self.buffer.can_transform(gt_child, base):
            T_gt_base = self.buffer.lookup(gt_child, base, None)
        else:
            self.warnings.append(f"ground truth is of {gt_child}, which tf does not connect to {base}: not evaluated")
            return None, {}
        truth_buffer, T_map_truth = TfBuffer(), T_map_gt @ T_gt_base
        truth_buffer.set_transform("map", "truth", stamps_gt, T_map_truth[:, :3, 3], quat2xyzw(tform2quat(T_map_truth)))
        T_map_start, ok = truth_buffer.lookup("map", "truth", trajectory.stamps_ns[:1], return_mask=True)
        if not ok[0]:
            self.warnings.append("ground truth does not cover the first scan's stamp: not evaluated")
            return None, {}
        anchor = trajectory.poses[0] @ np.linalg.inv(T_map_start[0])
        ground_truth = Trajectory(stamps_gt, anchor @ T_map_gt @ T_gt_base)
        result: dict = {"evaluation": {
            "reference": "ground_truth.tum",
            "alignment": ("none: the ground truth is expressed in the odometry frame, anchored at the first scan's "
                          "pose (as evo --align_origin), so both trajectories start at the same pose"),
            "ape_translation_m": "evo_ape tum ground_truth.tum <trajectory> (translation part, --t_max_diff 0.01)",
            "rpe_translation_m_per_1m": "evo_rpe tum ground_truth.tum <trajectory> --delta 1 --delta_unit m",
        }}
        for name, est in (("ndt", trajectory), ("odometry", odometry)):
            if est is not None:
                result[f"errors_{name}"] = odometry_errors(ground_truth, est)
        return ground_truth, result

    def _summary(self, front: LaserOdometry | None, elapsed_s: float) -> dict:
        steps = front.run.steps if front is not None else []
        summary: dict = {
            "bag": str(self.bag_path),
            "topic": self.options.topic,
            "scan_frame": self.scan_frame,
            "odometry_frame": self.odom_frame,
            "odometry_frame_parent": self.odometry_frame_parent(),
            "base_frame": self.base_frame or self.scan_frame,
            "odometry_source": self.odometry_source,
            "T_base_scan_xyz_yaw": [*map(float, self.T_base_scan[:3, 3]), float(tform2pose(self.T_base_scan)[2])],
            "init": self.options.init,
            "cell_size_m": self.options.cell_size_m or self.cell_size_m,
            "odometry_used": self._has_odometry(),
            "reference": self.options.reference,
            "scans_used": len(steps),
            "scans_skipped": dict(self.skipped),
            "scans_out_of_recording_order": self.reordered,
            "stamps_ignored": self.stamps_ignored,
            "scans_repeated": self.repeated,
            "options": asdict(self.options),
            "warnings": self.warnings,
        }
        if front is not None:
            counts = front.summary_counts()
            summary.update(counts)
            summary["pairs_matched"] = counts["pairs"] - counts["fallbacks"]
            summary["sources"] = {k: sum(1 for s in steps if s.source == k) for k in ("ndt", "search", "fallback")}
            scores = np.array([s.score for s in steps[1:]])
            if scores.size:
                summary["normalized_score"] = {"mean": float(scores.mean()), "min": float(scores.min()),
                                               "median": float(np.median(scores))}
                summary["time_per_pair_ms"] = {"mean": 1e3 * elapsed_s / scores.size, "total_s": elapsed_s}
        return summary


def run_front_end(bag_path: str | Path, options: NdtOdomOptions | None = None, keep_scans: bool = False) -> NdtOdomResult:
    """The laser-odometry front end of a bag, as ``ndt-odom`` computes it: for ``slam`` and scripts.

    ``result.front_end`` is the :class:`~bagtools.odometry.steps.FrontEndRun`
    (every scan: base pose in the odometry frame, points in the base frame,
    keyframes with their matches and covariances); ``result.odometry`` and
    ``result.ground_truth`` the bag's wheel odometry and reference at the scan
    stamps (None when absent); ``result.problem`` says why nothing could be
    registered. Pass ``NdtOdomOptions(use_odometry=False)`` to ignore the wheels, and ``keep_scans=True``
    for ``result.scans`` (the LaserScans of the steps, as decoded: what results.mcap re-publishes).
    """
    return NdtOdomPipeline(bag_path, options or NdtOdomOptions(), keep_scans=keep_scans).run()
