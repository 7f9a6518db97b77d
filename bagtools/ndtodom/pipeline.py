"""Laser odometry by 2D NDT scan matching: the robot's trajectory from a bag's LaserScans.

    NdtOdomPipeline(bag, options).run()
        _load_odometry()   tf and /odom: the odometry frame, the robot base frame, T_base_scan
        _read_scans()      every scan's valid points; scans with too few valid beams or a
                           stamp not after the previous scan are skipped and counted
        _match()           scans in order: initial guess, NDT match against the reference,
                           fallback to the guess on a poor score, chaining
        _evaluate()        ground truth of simulated bags, APE and RPE of NDT and odometry

Frames and chaining. Let W_k = T_odom_scan_k be the pose of the laser at scan k
in the odometry frame and T_base_scan the static mount of the laser on the
robot base. NDT gives the pose of the current scan in the reference scan's
frame, T_ref_cur, so W_cur = W_ref @ T_ref_cur (post-multiplication), and the
robot base is T_odom_base_k = W_k @ inv(T_base_scan). The first pose is the
odometry pose of the first scan (identity when the bag has no odometry).

Initial guess of the motion M from the previous scan to the current one (in
the laser frame): ``odom``: inv(T_base_scan) inv(O_prev) O_cur T_base_scan with
O = T_odom_base from tf at the two scan stamps (constant velocity for a pair
outside the odometry's time range); ``constant-velocity``: the previous
estimated motion, its planar [x y theta] scaled by the ratio of the time steps;
``zero``: identity. The match starts from inv(W_ref) W_prev M.

Reference: ``previous`` matches each scan against the one before it;
``keyframe`` keeps a reference scan until the robot has moved
``keyframe_distance_m`` or turned ``keyframe_angle_rad`` from it, or the match
score falls below ``keyframe_score_ratio`` of the first score against it.

Defaults, measured with bagtools simulate (60 s lap, realistic odometry noise;
APE rmse, wheel odometry 6.9 cm): ``--reference keyframe`` with 0.5 m cells and
the widened cell model gives 0.5 cm (1 m cells: 1.9 cm); ``--reference
previous`` 4.2 cm (1 m cells: 3.1 cm), since every scan adds its small matching
error while a keyframe is matched against about ten times less often. With the
paper's cell model the per-pair sideways bias (about 2 mm per 5 cm driven)
makes ``previous`` drift to about 10 cm, worse than the wheels.

Score: the NDT score divided by its maximum, 4 x the current scan's points (each
point contributes at most 1 per grid), so it is in [0, 1] whatever the beam
count. A match scoring below ``min_score`` (or failing) is replaced by the
initial guess and counted as a fallback.
"""

from __future__ import annotations

import time
from collections import Counter
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from bagtools.dataset import ScanStream, require_topic
from bagtools.errors import BagtoolsError
from bagtools.io import LASERSCAN_TYPES, ODOMETRY_TYPES, BagReader, TfArrays, TfCollector, decode_odometry, open_bag
from bagtools.ndt import MIN_SCAN_POINTS, NdtReference, match_scans
from bagtools.ndt.grid import CELL_MODELS
from bagtools.progress import progress
from bagtools.simtruth import read_ground_truth
from bagtools.tf import TfBuffer, TransformException
from bagtools.tf.repair import NO_SCAN_TRANSFORM_WARNING, repair_dynamic_tf
from bagtools.trajectory import Trajectory, ape_translation, rpe_translation
from bagtools.transforms import pose2tform, tform2pose

INIT_MODES = ("odom", "constant-velocity", "zero")
REFERENCE_MODES = ("previous", "keyframe")
ODOM_TOPIC = "/odom"


@dataclass(frozen=True)
class NdtOdomOptions:
    """How to run laser odometry.

    ``init``: 'odom', 'constant-velocity' or 'zero', or None for odom when the
    bag has odometry and constant velocity otherwise. ``cell_size_m``: NDT cell
    side (m). ``cell_model``: 'widened' (default: far less drift when chaining,
    see :mod:`bagtools.ndt.grid`) or 'paper'. ``min_score``: normalized score in [0, 1] below which a match
    falls back to its initial guess. ``scan_frame_offset``: (x m, y m, yaw rad)
    of the laser on the robot base, overriding (or standing in for) tf.
    """

    topic: str = "/scan"
    init: str | None = None
    reference: str = "keyframe"
    cell_size_m: float = 0.5
    cell_model: str = "widened"
    min_score: float = 0.1
    keyframe_distance_m: float = 0.5
    keyframe_angle_rad: float = 0.35
    keyframe_score_ratio: float = 0.7
    scan_frame_offset: tuple[float, float, float] | None = None
    max_iterations: int = 100

    def __post_init__(self) -> None:
        if self.init is not None and self.init not in INIT_MODES:
            raise BagtoolsError(f"--init must be one of {', '.join(INIT_MODES)}, got {self.init!r}")
        if self.reference not in REFERENCE_MODES:
            raise BagtoolsError(f"--reference must be one of {', '.join(REFERENCE_MODES)}, got {self.reference!r}")
        if not (np.isfinite(self.cell_size_m) and self.cell_size_m > 0):
            raise BagtoolsError(f"--cell-size must be a positive number of metres, got {self.cell_size_m}")
        if self.cell_model not in CELL_MODELS:
            raise BagtoolsError(f"--cell-model must be one of {', '.join(CELL_MODELS)}, got {self.cell_model!r}")
        if not 0.0 <= self.min_score <= 1.0:
            raise BagtoolsError(f"--min-score must be in [0, 1] (a normalized NDT score), got {self.min_score}")
        if self.keyframe_distance_m <= 0 or self.keyframe_angle_rad <= 0 or not 0 <= self.keyframe_score_ratio <= 1:
            raise BagtoolsError("keyframe thresholds must be positive (score ratio in [0, 1])")
        if self.scan_frame_offset is not None and (len(self.scan_frame_offset) != 3
                                                   or not np.isfinite(self.scan_frame_offset).all()):
            raise BagtoolsError(f"--scan-frame-offset must be three numbers X,Y,YAW, got {self.scan_frame_offset!r}")
        if self.max_iterations < 1:
            raise BagtoolsError(f"max_iterations must be at least 1, got {self.max_iterations}")


@dataclass
class NdtOdomResult:
    """Trajectories (base frame in the odometry frame) and what the writer needs.

    ``trajectory``: NDT; ``odometry``: wheel odometry at the same stamps (None
    without odometry); ``ground_truth``: simulator truth in the odometry frame
    (None when absent); ``scan_points``: each used scan's valid points (M,2) in
    its own frame; ``scan_poses``: W_k = T_odom_scan (N,4,4); ``problem``: set
    when nothing could be matched (the CLI exits 2 after writing what exists).
    """

    trajectory: Trajectory | None
    odometry: Trajectory | None
    ground_truth: Trajectory | None
    scan_points: list[np.ndarray]
    scan_poses: np.ndarray
    summary: dict = field(default_factory=dict)
    problem: str | None = None


def normalized_score(score: float, n_points: int) -> float:
    """NDT score / (4 x points): 1 when every point sits on a cell mean in all four grids."""
    return score / (4.0 * n_points) if n_points > 0 else 0.0


def _planar(T: np.ndarray) -> np.ndarray:
    """[x y theta] of a 4x4 transform (z, roll, pitch dropped)."""
    return tform2pose(T)


def _inv(T: np.ndarray) -> np.ndarray:
    """Inverse of rigid 4x4 transform(s)."""
    out = np.zeros_like(T)
    R_t = np.swapaxes(T[..., :3, :3], -1, -2)
    out[..., :3, :3] = R_t
    out[..., :3, 3] = -np.einsum("...ij,...j->...i", R_t, T[..., :3, 3])
    out[..., 3, 3] = 1.0
    return out


class NdtOdomPipeline:
    """Laser odometry of one bag (see the module docstring)."""

    def __init__(self, bag_path: str | Path, options: NdtOdomOptions) -> None:
        self.bag_path = Path(bag_path)
        self.options = options
        self.skipped: Counter[str] = Counter()
        self.warnings: list[str] = []
        self.buffer: TfBuffer | None = None
        self.odom_frame = "odom"
        self.base_frame: str | None = None
        self.odometry_source: str | None = None
        self.T_base_scan = np.eye(4)
        self.scan_frame = ""

    def run(self) -> NdtOdomResult:
        with open_bag(self.bag_path) as bag:
            self._require_scan_topic(bag)
            self._load_odometry(bag)
            stamps, points = self._read_scans(bag)
            self.warnings[:0] = list(bag.warnings)
            self._scan_offset(stamps)
            init = self._init_mode()
            if len(stamps) == 0:
                problem = (f"no usable scan on {self.options.topic}: every scan was skipped "
                           f"({', '.join(f'{n} {r}' for r, n in self.skipped.items()) or 'none recorded'})")
                return NdtOdomResult(None, None, None, [], np.zeros((0, 4, 4)), self._summary(init, 0, []), problem)
            odometry = self._odometry_at(stamps)
            W, pairs = self._match(stamps, points, odometry, init)
            T_base = W @ _inv(self.T_base_scan)
            trajectory = Trajectory(stamps, T_base)
            odom_traj = None if odometry is None else Trajectory(stamps, odometry[0])
            summary = self._summary(init, len(stamps), pairs)
            if len(stamps) == 1:
                self.warnings.append(f"only one usable scan on {self.options.topic}: the trajectory is its one pose, "
                                     "nothing was matched")
            truth, evaluation = self._evaluate(bag, trajectory, odom_traj)
            summary.update(evaluation)
            summary["warnings"] = self.warnings
        return NdtOdomResult(trajectory, odom_traj, truth, points, W, summary)

    # -- steps -------------------------------------------------------------------

    def _require_scan_topic(self, bag: BagReader) -> None:
        require_topic(bag, self.options.topic, LASERSCAN_TYPES, "LaserScan")

    def _load_odometry(self, bag: BagReader) -> None:
        """Build the tf buffer (with /odom added when tf lacks it) and pick the odometry and base frames."""
        collector = TfCollector()
        collector.check(bag)
        odom_samples = []
        has_odom_topic = ODOM_TOPIC in bag.topics and bag.topics[ODOM_TOPIC].msgtype in ODOMETRY_TYPES
        topics = [t for t in collector.topics if t in bag.topics] + ([ODOM_TOPIC] if has_odom_topic else [])
        for rec in bag.messages(topics):
            if rec.topic == ODOM_TOPIC:
                odom_samples.append(decode_odometry(rec.msg))
            else:
                collector.add(rec)
        dynamic, static = collector.arrays()
        parents = np.array([p.lstrip("/") for p in dynamic.parent], dtype=object)
        children = np.array([c.lstrip("/") for c in dynamic.child], dtype=object)
        if odom_samples:
            self.odom_frame = odom_samples[0].frame_id.lstrip("/") or "odom"
            self.base_frame = odom_samples[0].child_frame_id.lstrip("/") or None
        if self.base_frame is None:
            below_odom = sorted(set(children[parents == self.odom_frame]))
            self.base_frame = below_odom[0] if below_odom else None
        if self.base_frame is not None:
            edge = (parents == self.odom_frame) & (children == self.base_frame)
            if edge.any():
                self.odometry_source = f"/tf {self.odom_frame} -> {self.base_frame}"
                dynamic = repair_dynamic_tf(dynamic, self.warnings)[0]
            elif odom_samples:
                n = len(odom_samples)
                dynamic = TfArrays.concatenate([dynamic, TfArrays(
                    np.full(n, self.odom_frame, dtype=object), np.full(n, self.base_frame, dtype=object),
                    np.array([s.stamp_ns for s in odom_samples], dtype=np.int64),
                    np.array([s.position_m for s in odom_samples]), np.array([s.orientation_xyzw for s in odom_samples]))])
                self.odometry_source = f"{ODOM_TOPIC} ({self.odom_frame} -> {self.base_frame})"
                dynamic = repair_dynamic_tf(dynamic, self.warnings)[0]
        try:
            self.buffer = TfBuffer.from_arrays(dynamic, static, skip_invalid=True)
        except BagtoolsError as err:
            raise BagtoolsError(f"the bag's tf data cannot be used: {err.problem}", bag.path) from err

    def _read_scans(self, bag: BagReader) -> tuple[np.ndarray, list[np.ndarray]]:
        """Stamps (N,) int64 and valid points (M_k,2) of the usable scans, in bag order."""
        stamps: list[int] = []
        points: list[np.ndarray] = []
        stream = ScanStream(bag, self.options.topic, increasing=True, min_returns=MIN_SCAN_POINTS, desc="reading scans")
        for item in stream:
            if not self.scan_frame:
                self.scan_frame = item.scan.frame_id.lstrip("/")
            stamps.append(item.scan.stamp_ns)
            points.append(item.scan.points_xy())
        self.skipped.update(stream.skipped)
        self.warnings.extend(stream.warnings())
        return np.asarray(stamps, dtype=np.int64), points

    def _scan_offset(self, stamps: np.ndarray) -> None:
        """T_base_scan: from --scan-frame-offset, else tf, else identity with a warning."""
        if self.options.scan_frame_offset is not None:
            self.T_base_scan = pose2tform(np.asarray(self.options.scan_frame_offset, dtype=np.float64))
            return
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

    def _has_odometry(self) -> bool:
        return self.odometry_source is not None

    def _init_mode(self) -> str:
        init = self.options.init
        if init is None:
            return "odom" if self._has_odometry() else "constant-velocity"
        if init == "odom" and not self._has_odometry():
            raise BagtoolsError(f"--init odom needs wheel odometry, but the bag has no {ODOM_TOPIC} and no "
                                f"'{self.odom_frame}' frame with a child in /tf (use --init constant-velocity)",
                                self.bag_path)
        return init

    def _odometry_at(self, stamps: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
        """(T_odom_base (N,4,4), valid (N,)) at the scan stamps; stamps outside the data take the nearest end."""
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
        return T, valid

    def _match(self, stamps: np.ndarray, points: list[np.ndarray], odometry, init: str) -> tuple[np.ndarray, list]:
        """Scan poses W (N,4,4) and per-pair records (time, normalized score, fallback, reason)."""
        opts = self.options
        n = len(stamps)
        T_bs, T_sb = self.T_base_scan, _inv(self.T_base_scan)
        W = np.zeros((n, 4, 4))
        W[0] = (odometry[0][0] if odometry is not None else np.eye(4)) @ T_bs
        odom_motion = odom_valid = None
        if odometry is not None:
            O, valid = odometry
            odom_motion = T_sb @ _inv(O[:-1]) @ O[1:] @ T_bs  # (n-1,4,4), laser frame
            odom_valid = valid[:-1] & valid[1:]
        pairs: list[tuple[float, float, bool, str]] = []
        ref_index = 0
        reference = NdtReference.from_points(points[0], opts.cell_size_m, opts.cell_model) if n > 1 else None
        ref_first_score: float | None = None
        for k in progress(range(1, n), total=n - 1, desc="matching", unit="scan"):
            guess = self._guess(k, stamps, W, init, odom_motion, odom_valid)
            W_guess = W[k - 1] @ guess
            t0 = time.perf_counter()
            result = match_scans(points[k], reference, initial_pose=_planar(_inv(W[ref_index]) @ W_guess),
                                 max_iterations=opts.max_iterations)
            score = normalized_score(result.score, result.n_points)
            fallback = result.score <= 0.0 or score < opts.min_score
            W[k] = W_guess if fallback else W[ref_index] @ pose2tform(result.pose)
            new_reference = True
            if opts.reference == "keyframe" and not fallback:
                if ref_first_score is None:
                    ref_first_score = score
                motion = _planar(_inv(W[ref_index]) @ W[k])
                new_reference = (np.hypot(motion[0], motion[1]) >= opts.keyframe_distance_m
                                 or abs(motion[2]) >= opts.keyframe_angle_rad
                                 or score < opts.keyframe_score_ratio * ref_first_score)
            if new_reference and k + 1 < n:
                ref_index, ref_first_score = k, None
                reference = NdtReference.from_points(points[k], opts.cell_size_m, opts.cell_model)
            reason = ("" if not fallback else result.reason if result.score <= 0.0
                      else f"normalized score below {opts.min_score:g}")
            pairs.append((time.perf_counter() - t0, score, fallback, reason))
        return W, pairs

    def _guess(self, k: int, stamps: np.ndarray, W: np.ndarray, init: str, odom_motion, odom_valid) -> np.ndarray:
        """Motion guess from scan k-1 to scan k in the laser frame (4x4)."""
        if init == "odom" and odom_motion is not None and odom_valid[k - 1]:
            return odom_motion[k - 1]
        if init == "zero" or k < 2:
            return np.eye(4)
        previous = _planar(_inv(W[k - 2]) @ W[k - 1])
        ratio = (stamps[k] - stamps[k - 1]) / (stamps[k - 1] - stamps[k - 2])
        return pose2tform(previous * ratio)

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
        truth_buffer = TfBuffer.from_arrays(_tf_arrays("map", "truth", stamps_gt, T_map_gt @ T_gt_base))
        T_map_start, ok = truth_buffer.lookup("map", "truth", trajectory.stamps_ns[:1], return_mask=True)
        if not ok[0]:
            self.warnings.append("ground truth does not cover the first scan's stamp: not evaluated")
            return None, {}
        anchor = trajectory.poses[0] @ _inv(T_map_start[0])
        ground_truth = Trajectory(stamps_gt, anchor @ T_map_gt @ T_gt_base)
        result: dict = {"evaluation": {
            "reference": "ground_truth.tum",
            "alignment": ("none: the ground truth is expressed in the odometry frame, anchored at the first scan's "
                          "pose (as evo --align_origin), so both trajectories start at the same pose"),
            "ape_translation_m": "evo_ape tum ground_truth.tum <trajectory> (translation part, --t_max_diff 0.01)",
            "rpe_translation_m_per_1m": "evo_rpe tum ground_truth.tum <trajectory> --delta 1 --delta_unit m",
        }}
        for name, est in (("ndt", trajectory), ("odometry", odometry)):
            if est is None:
                continue
            entry: dict = {}
            try:
                entry["ape_translation_m"] = ape_translation(ground_truth, est).as_dict()
            except BagtoolsError as err:
                entry["ape_translation_m"] = {"unavailable": err.problem}
            try:
                entry["rpe_translation_m_per_1m"] = rpe_translation(ground_truth, est, delta_m=1.0).as_dict()
            except BagtoolsError as err:
                entry["rpe_translation_m_per_1m"] = {"unavailable": err.problem}
            result[f"errors_{name}"] = entry
        return ground_truth, result

    def _summary(self, init: str, n_used: int, pairs: list) -> dict:
        times = np.array([p[0] for p in pairs]) * 1e3
        scores = np.array([p[1] for p in pairs])
        fallbacks = int(sum(p[2] for p in pairs))
        summary: dict = {
            "bag": str(self.bag_path),
            "topic": self.options.topic,
            "scan_frame": self.scan_frame,
            "odometry_frame": self.odom_frame,
            "base_frame": self.base_frame or self.scan_frame,
            "odometry_source": self.odometry_source,
            "T_base_scan_xyz_yaw": [*map(float, self.T_base_scan[:3, 3]), float(_planar(self.T_base_scan)[2])],
            "init": init,
            "reference": self.options.reference,
            "scans_used": n_used,
            "scans_skipped": dict(self.skipped),
            "pairs_matched": len(pairs) - fallbacks,
            "fallbacks": fallbacks,
            "fallback_reasons": dict(Counter(p[3] for p in pairs if p[2])),
            "options": asdict(self.options),
            "warnings": self.warnings,
        }
        if pairs:
            summary["time_per_pair_ms"] = {"mean": float(times.mean()), "median": float(np.median(times)),
                                           "p95": float(np.percentile(times, 95)), "max": float(times.max()),
                                           "total_s": float(times.sum() / 1e3)}
            summary["normalized_score"] = {"mean": float(scores.mean()), "min": float(scores.min()),
                                           "median": float(np.median(scores))}
        return summary


def _tf_arrays(parent: str, child: str, stamps_ns: np.ndarray, T: np.ndarray) -> TfArrays:
    """Poses T (N,4,4) of ``child`` in ``parent`` as TfArrays (ROS x, y, z, w quaternions)."""
    from bagtools.transforms import quat2xyzw, tform2quat

    n = len(stamps_ns)
    return TfArrays(np.full(n, parent, dtype=object), np.full(n, child, dtype=object),
                    np.asarray(stamps_ns, dtype=np.int64), T[:, :3, 3].copy(), quat2xyzw(tform2quat(T)))
