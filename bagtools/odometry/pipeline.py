"""Laser odometry by 2D NDT scan matching: the robot's trajectory from a bag's LaserScans.

    NdtOdomPipeline(bag, options).run()
        LaserDataset.read()   the dataset (bagtools.dataset.laser): tf and /odom (the odometry and base frames,
                              repaired samples), every usable scan's valid points in recording order, the laser's
                              mount, the odometry at the scans' stamps
        register_scans()      the scans in order through LaserOdometry (bagtools.odometry.frontend): guesses,
                              gating, grid search when a guess cannot be trusted, NDT refinement, checks
        _evaluate()           /ground_truth of the bag (simulated, or a reference trajectory), APE and RPE

Frames: the front end works in the robot base frame (scan points moved by
T_base_scan); poses are T_odom_base, starting at the odometry pose of the
first scan (identity when the bag has no odometry). The summary counts the
pairs that needed a search, fell back to their guess, contradicted the
odometry, or moved faster than the robot can; warnings say each kind once.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from bagtools.dataset import ScanClock
from bagtools.dataset.laser import ODOM_TOPIC, LaserDataset, ScanInputs
from bagtools.errors import BagtoolsError
from bagtools.io import BagReader, LaserScanArrays, open_bag
from bagtools.odometry.frontend import LaserOdometry
from bagtools.odometry.options import NdtOdomOptions, cell_size_for
from bagtools.odometry.steps import FrontEndRun
from bagtools.scan_matching import MIN_SCAN_POINTS
from bagtools.progress import progress
from bagtools.simtruth import read_ground_truth
from bagtools.tf import TfBuffer
from bagtools.trajectory import Trajectory
from bagtools.trajectory.evaluate import odometry_errors
from bagtools.transforms import pose2tform, quat2xyzw, tform2pose, tform2quat


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


class NdtOdomPipeline:
    """Laser odometry of one bag (see the module docstring)."""

    def __init__(self, bag_path: str | Path, options: NdtOdomOptions, keep_scans: bool = False) -> None:
        """``keep_scans``: keep each step's LaserScan (``NdtOdomResult.scans``, for results.mcap)."""
        self.bag_path = Path(bag_path)
        self.options = options
        self.dataset = laser_dataset(options, keep_scans)
        self.warnings = self.dataset.warnings  # one list: the dataset's repairs first, then the run's
        self.cell_size_m: float | None = None

    def run(self) -> NdtOdomResult:
        dataset = self.dataset
        with open_bag(self.bag_path) as bag:
            inputs = dataset.read(bag)
            stamps = inputs.stamps_ns
            if self.options.init == "odom" and not dataset.has_odometry:
                raise BagtoolsError(f"--init odom needs wheel odometry, but the bag has no {ODOM_TOPIC} and no "
                                    f"'{dataset.odom_frame}' frame with a child in /tf (use --init auto)",
                                    self.bag_path)
            if len(stamps) == 0:
                return NdtOdomResult(None, None, None, FrontEndRun(), self._summary(None, 0.0),
                                     dataset.no_scan_problem(bag))
            t0 = time.perf_counter()
            front, poses = register_scans(inputs, self.options)
            elapsed_s = time.perf_counter() - t0
            self.cell_size_m = front.options.cell_size_m
            trajectory = Trajectory(stamps, pose2tform(poses))
            odom_traj = None if inputs.odometry is None else Trajectory(stamps, inputs.odometry[0])
            dataset.check_frozen(inputs)
            self.warnings.extend(front.warnings(self.options.topic))
            if len(stamps) == 1:
                self.warnings.append(f"only one usable scan on {self.options.topic}: the trajectory is its one pose, "
                                     "nothing was matched")
            summary = self._summary(front, elapsed_s)
            truth, evaluation = self._evaluate(bag, trajectory, odom_traj)
            summary.update(evaluation)
            summary["warnings"] = self.warnings
        front.run.warnings = list(self.warnings)
        return NdtOdomResult(trajectory, odom_traj, truth, front.run, summary, scans=dataset.scans,
                             T_base_scan=dataset.T_base_scan, clock=inputs.clock)

    # -- steps -------------------------------------------------------------------

    def _evaluate(self, bag: BagReader, trajectory: Trajectory, odometry: Trajectory | None) -> tuple[Trajectory | None, dict]:
        """Ground truth in the odometry frame, anchored at the first scan, and the errors of NDT and odometry."""
        truth = read_ground_truth(bag, warnings=self.warnings)
        if truth is None:
            return None, {}
        stamps_gt, T_map_gt, gt_child = truth
        gt_child = gt_child.lstrip("/")
        if self.dataset.buffer is None:
            return None, {}
        base = self.dataset.base_frame or self.dataset.scan_frame
        if gt_child == base:
            T_gt_base = np.eye(4)
        elif self.dataset.buffer.can_transform(gt_child, base):
            T_gt_base = self.dataset.buffer.lookup(gt_child, base, None)
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
        dataset = self.dataset
        steps = front.run.steps if front is not None else []
        summary: dict = {
            "bag": str(self.bag_path),
            "topic": self.options.topic,
            "scan_frame": dataset.scan_frame,
            "odometry_frame": dataset.odom_frame,
            "odometry_frame_parent": dataset.odometry_frame_parent(),
            "base_frame": dataset.base_frame or dataset.scan_frame,
            "odometry_source": dataset.odometry_source,
            "T_base_scan_xyz_yaw": [*map(float, dataset.T_base_scan[:3, 3]), float(tform2pose(dataset.T_base_scan)[2])],
            "init": self.options.init,
            "cell_size_m": self.options.cell_size_m or self.cell_size_m,
            "odometry_used": dataset.has_odometry,
            "reference": self.options.reference,
            "scans_used": len(steps),
            "scans_skipped": dict(dataset.skipped),
            "scans_out_of_recording_order": dataset.reordered,
            "stamps_ignored": dataset.stamps_ignored,
            "scans_repeated": dataset.repeated,
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


def laser_dataset(options: NdtOdomOptions, keep_scans: bool = False) -> LaserDataset:
    """The dataset the front end reads with ``options`` (topic, odometry, laser mount): scans with at least the
    matcher's MIN_SCAN_POINTS returns."""
    return LaserDataset(options.topic, MIN_SCAN_POINTS, use_odometry=options.use_odometry,
                        scan_frame_offset=options.scan_frame_offset, keep_scans=keep_scans)


def register_scans(inputs: ScanInputs, options: NdtOdomOptions) -> tuple[LaserOdometry, np.ndarray]:
    """The laser odometry of a dataset's scans (:meth:`LaserDataset.read`): every scan in recording order through
    the front end (:class:`~bagtools.odometry.frontend.LaserOdometry`, NDT cells sized by the scans unless
    ``options`` give them), points in the base frame, with the wheel odometry's pose when trusted. Returns the
    front end and the base's poses (N, 3) [x, y, theta] in the odometry frame at the scans' stamps (stamp order)."""
    order, odometry = inputs.order, inputs.odometry
    front = LaserOdometry(options.front_end(cell_size_for([inputs.points[i] for i in order])))
    odom_xyt = None if odometry is None else np.where(odometry[1][order][:, None], tform2pose(odometry[0][order]),
                                                      np.nan)
    for k, i in enumerate(progress(order, total=len(order), desc="matching", unit="scan")):
        odom = None if odom_xyt is None or not np.isfinite(odom_xyt[k]).all() else odom_xyt[k]
        front.register(int(inputs.stamps_ns[i]), inputs.points_base(i), odom)
    poses = np.empty((len(inputs.stamps_ns), 3))
    poses[order] = front.run.poses()  # the steps in recording order, the trajectory in stamp order
    return front, poses


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
