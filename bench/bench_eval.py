"""``bagtools eval``: a trajectory's APE and RPE against evo's own computation of the same numbers.

A planar 13 600-pose trajectory (the Intel log's length) and a drifting
estimate of it at the same stamps. The value is bagtools' time for the APE
(no alignment and SE(2)-aligned), the RPE per metre and the error over 20
poses; the baseline is evo's time for its APE, aligned APE and RPE on the same
pair (association included on both sides). Target: no slower than evo.

Reading: a TUM file of 1 000 000 poses (3 000 000 without --quick) read by
``read_tum`` (every line checked), against evo's ``file_interface.read_tum_trajectory_file``
on the same file.
"""

from __future__ import annotations

import numpy as np

from bench.common import Row, best_time_s

T0_NS = 1_700_000_000_000_000_000


def _pair(n: int):
    from bagtools.trajectory import Trajectory
    from bagtools.transforms import pose2tform

    rng = np.random.default_rng(5)
    yaw = np.cumsum(rng.normal(0.0, 0.03, n))
    xy = np.cumsum(0.1 * np.c_[np.cos(yaw), np.sin(yaw)], axis=0)
    stamps = T0_NS + np.arange(n, dtype=np.int64) * 200_000_000
    drift = np.c_[np.cumsum(rng.normal(0, 0.01, (n, 2)), axis=0), np.cumsum(rng.normal(0, 0.002, n))]
    return Trajectory(stamps, pose2tform(np.c_[xy, yaw])), Trajectory(stamps, pose2tform(np.c_[xy, yaw] + drift))


def _ours(ref, est) -> None:
    from bagtools.trajectory.evaluate import evaluate

    evaluate(est, ref, gap=20, align=True)


def _evo(ref, est) -> None:
    from evo.core import metrics, sync
    from evo.core.trajectory import PoseTrajectory3D

    r = PoseTrajectory3D(poses_se3=list(ref.poses), timestamps=ref.stamps_ns / 1e9)
    e = PoseTrajectory3D(poses_se3=list(est.poses), timestamps=est.stamps_ns / 1e9)
    r, e = sync.associate_trajectories(r, e, max_diff=0.01)
    for aligned in (False, True):
        if aligned:
            e.align(r, correct_scale=False)
        ape = metrics.APE(metrics.PoseRelation.translation_part)
        ape.process_data((r, e))
    rpe = metrics.RPE(metrics.PoseRelation.translation_part, delta=1.0, delta_unit=metrics.Unit.meters, all_pairs=False)
    rpe.process_data((r, e))


def _read_rows(n: int) -> list[Row]:
    import tempfile
    from pathlib import Path

    from evo.tools import file_interface

    from bagtools.trajectory import read_tum, write_tum

    ref, _ = _pair(n)
    with tempfile.TemporaryDirectory(prefix="bench_eval_") as tmp:
        path = Path(tmp) / "big.tum"
        write_tum(path, ref)
        ours_s = best_time_s(lambda: read_tum(path), repeat=1)
        evo_s = best_time_s(lambda: file_interface.read_tum_trajectory_file(str(path)), repeat=1)
    return [Row("eval", f"read a TUM file of {n} poses", ours_s, "s", "evo's read_tum_trajectory_file", evo_s, False,
                "<= evo's time")]


def run(quick: bool) -> list[Row]:
    n = 2000 if quick else 13_600
    ref, est = _pair(n)
    ours_s = best_time_s(lambda: _ours(ref, est))
    evo_s = best_time_s(lambda: _evo(ref, est))
    return [Row("eval", f"APE, aligned APE, RPE per metre and error over 20 poses of {n} poses", ours_s, "s",
                "evo (APE, aligned APE, RPE per metre)", evo_s, False, "<= evo's time"),
            *_read_rows(1_000_000 if quick else 3_000_000)]
