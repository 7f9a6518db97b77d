"""A stand-in for the laser-odometry front end, for tests only: a FrontEndRun built from a bag's /ground_truth.

The real front end (``bagtools.odometry``) matches scans; this one takes the true
base pose at every scan, picks keyframes the way the front end does (every
``keyframe_distance_m`` or ``keyframe_angle_rad``), and corrupts the motion
between consecutive keyframes with a drift like a laser odometry's: a scale
error on the translation, a heading bias per metre driven and white noise. The
covariance of each edge is the noise it was given (times ``covariance_scale``),
so the back end sees the drift it must correct. Scan points are the bag's,
moved into the base frame by the bag's tf.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from bagtools.dataset import ScanStream
from bagtools.io import open_bag, read_tf_arrays
from bagtools.commands.ndt_odom import NdtOdomResult
from bagtools.odometry.steps import FrontEndRun, ScanStep
from bagtools.simtruth import read_ground_truth
from bagtools.tf import TfBuffer
from bagtools.trajectory import Trajectory
from bagtools.transforms import pose2tform, quat2xyzw, se2_between, se2_compose, tform2pose, tform2quat, wrap_to_pi


@dataclass(frozen=True)
class Drift:
    """Errors of the stand-in odometry per keyframe step: scale (fraction), heading bias (rad per m), noise (m, rad)."""

    scale: float = 0.01
    heading_bias_rad_per_m: float = 0.004
    noise_m: float = 0.01
    noise_rad: float = 0.004


def front_end_from_truth(bag_path: str | Path, topic: str = "/scan", drift: Drift = Drift(), seed: int = 0,
                         keyframe_distance_m: float = 0.5, keyframe_angle_rad: float = 0.35,
                         covariance_scale: float = 1.0) -> FrontEndRun:
    """The stand-in FrontEndRun of a bag with /ground_truth (see the module docstring)."""
    rng = np.random.default_rng(seed)
    with open_bag(bag_path) as bag:
        stamps_gt, T_map_gt, gt_frame = read_ground_truth(bag)
        dynamic, static = read_tf_arrays(bag)
        tf = TfBuffer.from_arrays(dynamic, static, skip_invalid=True)
        stamps: list[int] = []
        points: list[np.ndarray] = []
        frame = ""
        for item in ScanStream(bag, topic, increasing=True, min_returns=5, desc=None):
            frame = item.scan.frame_id.lstrip("/")
            stamps.append(item.scan.stamp_ns)
            points.append(item.scan.points_xy())
    base = gt_frame.lstrip("/")
    T_base_scan = tf.lookup(base, frame, None) if frame != base and tf.can_transform(base, frame) else np.eye(4)
    truth = TfBuffer()
    truth.set_transform("map", base, stamps_gt, T_map_gt[:, :3, 3], quat2xyzw(tform2quat(T_map_gt)))
    stamps_ns = np.array(stamps, dtype=np.int64)
    T, ok = truth.lookup("map", base, np.clip(stamps_ns, stamps_gt[0], stamps_gt[-1]), return_mask=True)
    true_xyt = tform2pose(T)
    R, t = T_base_scan[:2, :2], T_base_scan[:2, 3]
    points_base = [p @ R.T + t for p in points]

    run = FrontEndRun()
    sigma = np.array([drift.noise_m, drift.noise_m, drift.noise_rad])
    pose = np.zeros(3)
    key = 0
    for k in range(len(stamps_ns)):
        if k == 0:
            run.steps.append(ScanStep(int(stamps_ns[0]), pose.copy(), points_base[0], -1, np.zeros(3),
                                      np.diag(sigma**2) * covariance_scale, 1.0, "first", True))
            continue
        motion = se2_between(true_xyt[key], true_xyt[k])
        dist = float(np.hypot(motion[0], motion[1]))
        is_key = dist >= keyframe_distance_m or abs(motion[2]) >= keyframe_angle_rad or k == len(stamps_ns) - 1
        noisy = motion.copy()
        noisy[:2] *= 1.0 + drift.scale
        noisy[2] += drift.heading_bias_rad_per_m * dist
        noisy += rng.normal(0.0, 1.0, 3) * sigma * (1.0 if is_key else 0.3)
        noisy[2] = wrap_to_pi(noisy[2])
        cur = se2_compose(run.steps[key].pose, noisy)
        cur[2] = wrap_to_pi(cur[2])
        run.steps.append(ScanStep(int(stamps_ns[k]), cur, points_base[k], key, noisy,
                                  np.diag(sigma**2) * covariance_scale, 0.8, "ndt", is_key))
        if is_key:
            key = k
    run.counts = {"scans": len(run.steps), "keyframes": len(run.keyframe_indexes)}
    if not ok.all():
        run.warnings.append("stand-in: some scans lie outside /ground_truth's time range")
    return run


def true_poses_at_scans(bag_path: str | Path, topic: str = "/scan") -> tuple[np.ndarray, np.ndarray]:
    """(stamps_ns (N,), [x, y, theta] (N,3)) of the base at the usable scans, from /ground_truth."""
    with open_bag(bag_path) as bag:
        stamps_gt, T_map_gt, gt_frame = read_ground_truth(bag)
        stamps = np.array([item.scan.stamp_ns for item in ScanStream(bag, topic, increasing=True, min_returns=5,
                                                                        desc=None)], dtype=np.int64)
    truth = TfBuffer()
    truth.set_transform("map", gt_frame.lstrip("/"), stamps_gt, T_map_gt[:, :3, 3], quat2xyzw(tform2quat(T_map_gt)))
    T = truth.lookup("map", gt_frame.lstrip("/"), np.clip(stamps, stamps_gt[0], stamps_gt[-1]))
    return stamps, tform2pose(T)


def as_front_end_result(bag_path: str | Path, run: FrontEndRun, with_truth: bool = True) -> NdtOdomResult:
    """``run`` as the front end's result: the trajectory, and /ground_truth in the run's odometry frame anchored
    at its first scan (as ``ndt-odom`` gives it; None with ``with_truth`` False or a bag without it)."""
    stamps = run.stamps_ns()
    trajectory = Trajectory(stamps, pose2tform(run.poses()).reshape(-1, 4, 4))
    truth = None
    with open_bag(bag_path) as bag:
        found = read_ground_truth(bag) if with_truth else None
    base = "base_footprint"
    if found is not None:
        stamps_gt, T_map_gt, base = found
        base = base.lstrip("/")
        buffer = TfBuffer()
        buffer.set_transform("map", base, stamps_gt, T_map_gt[:, :3, 3], quat2xyzw(tform2quat(T_map_gt)))
        T_start = buffer.lookup("map", base, stamps[:1])[0]
        truth = Trajectory(stamps_gt, trajectory.poses[0] @ np.linalg.inv(T_start) @ T_map_gt)
    return NdtOdomResult(trajectory, None, truth, run, {"base_frame": base, "warnings": list(run.warnings)})


def standin(drift: Drift = Drift(), seed: int = 0):
    """A front end for :class:`~bagtools.commands.slam.SlamPipeline`: :func:`front_end_from_truth` as the front end's result."""
    def front_end(bag_path, options) -> NdtOdomResult:
        return as_front_end_result(bag_path, front_end_from_truth(bag_path, options.topic, drift, seed))
    return front_end


#: The stand-in's drift on simulated bags: about what NDT laser odometry does there (a few mm per keyframe).
SIM_DRIFT = Drift(scale=0.01, heading_bias_rad_per_m=0.003, noise_m=0.003, noise_rad=0.002)
#: The stand-in's drift on the CSAIL log: end point some 10 m off after its 380 m.
CSAIL_DRIFT = Drift(scale=0.01, heading_bias_rad_per_m=0.002, noise_m=0.01, noise_rad=0.004)
