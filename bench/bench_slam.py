"""``bagtools slam``: speed of the whole run against the bag's own duration, and accuracy against the front end.

Speed: seconds of recording processed per second of the whole command (front
end, loop closure, GTSAM, the map, the errors, writing every output) on the
real CSAIL log with and without its odometry (396 s of data, 406 scans of 361
beams) when ``../shared/data/real`` is there, else on a simulated figure eight.
Target: at least 10 (the run takes at most a tenth of the bag's duration, one
core). Baseline in the same run: the front end alone on the same bag, so the
ratio is what loop closure, the graph and the map add.

Accuracy: APE after an SE(2) alignment of the optimized trajectory on a long
simulated figure eight with high wheel-odometry noise (target 2 cm), against
the front end's; on the CSAIL log, APE and the error between scans 20 apart
against its reference (GMapping's trajectory). And how good that reference is
from one scan to the next: the heading change between consecutive scans of
the optimized trajectory and of the reference, each against an independent
point-to-plane ICP of the two scans (Open3D; no target: it says how much of
the 20-scan error is the reference's own).
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np

from bagtools.commands.slam import SlamOptions, SlamPipeline, SlamResult, laser_odometry, write_slam
from bagtools.transforms import se2_between, tform2pose, wrap_to_pi
from bench.bench_ndt import point_to_plane_icp
from bench.common import Row
from bagtools_simulate.pipeline import SimConfig, simulate_bag

REAL_DIR = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "real"


def _whole_run_s(bag: Path, options: SlamOptions, out: Path) -> tuple[float, SlamResult]:
    t0 = time.perf_counter()
    result = SlamPipeline(bag, options).run()
    write_slam(result, out, force=True)
    return time.perf_counter() - t0, result


def _heading_vs_icp_deg(result: SlamResult) -> tuple[float, float]:
    """Median |heading change between consecutive scans - ICP's| (deg) of (the optimized trajectory, the
    reference); the median, as ICP from the reference's guess fails on a few pairs (by 10 degrees and more)."""
    steps = result.front_end.front_end.steps
    ours = tform2pose(result.trajectory.poses).reshape(-1, 3)
    truth = result.ground_truth
    at = np.clip(np.searchsorted(truth.stamps_ns, result.trajectory.stamps_ns), 0, len(truth) - 1)
    ref = tform2pose(truth.poses[at]).reshape(-1, 3)
    ours_step, ref_step = se2_between(ours[:-1], ours[1:]), se2_between(ref[:-1], ref[1:])
    icp = np.array([point_to_plane_icp(steps[k + 1].points_base, steps[k].points_base, ref_step[k])
                    for k in range(len(steps) - 1)])
    ours_off, ref_off = (np.degrees(np.abs(wrap_to_pi(step[:, 2] - icp[:, 2]))) for step in (ours_step, ref_step))
    return float(np.median(ours_off)), float(np.median(ref_off))


def _front_end_s(bag: Path, options: SlamOptions) -> float:
    t0 = time.perf_counter()
    laser_odometry(bag, options)
    return time.perf_counter() - t0


def _duration_s(bag: Path) -> float:
    from bagtools.io import open_bag

    with open_bag(bag) as reader:
        stamps = [rec.log_time_ns for rec in reader.messages(["/scan"])]
    return (stamps[-1] - stamps[0]) / 1e9


def run(quick: bool) -> list[Row]:
    rows: list[Row] = []
    with tempfile.TemporaryDirectory(prefix="bench_slam_") as tmp:
        sim = Path(tmp) / "figure8"
        simulate_bag(sim, SimConfig(duration_s=120.0 if quick else 600.0, route="figure8", odom_noise="high",
                                    cloud=False, seed=3))
        cases = [("simulated figure eight, high odometry noise", sim, SlamOptions())]
        if REAL_DIR.is_dir() and not quick:
            cases = [("CSAIL log with odometry", REAL_DIR / "csail_odom", SlamOptions()),
                     ("CSAIL log, scans only", REAL_DIR / "csail_scans", SlamOptions(use_odometry=False)),
                     *cases]
        for label, bag, options in cases:
            duration = _duration_s(bag)
            whole_s, result = _whole_run_s(bag, options, Path(tmp) / "out")
            summary = result.summary
            front_s = _front_end_s(bag, options)
            rows.append(Row("slam", f"bag seconds per second, whole run: {label} ({duration:.0f} s, "
                                    f"{summary['scans']} scans, {summary['loop_closure']['accepted']} loops)",
                            duration / whole_s, "x real time", "front end alone", duration / front_s, True,
                            ">= 10 (a tenth of the bag's duration)"))
            if "errors_slam" in summary:
                slam, front = summary["errors_slam"], summary["errors_front_end"]
                rows.append(Row("slam", f"APE after SE(2) alignment, {label} ({duration:.0f} s)",
                                slam["ape_aligned_m"]["rmse"], "m", "front end alone",
                                front["ape_aligned_m"]["rmse"], False, "<= 0.02 m" if bag == sim else "<= 0.3 m"))
                if bag != sim:  # the real logs' reference is GMapping's trajectory
                    rows.append(Row("slam", f"relative error between scans 20 apart (mean), {label}",
                                    slam["relative_gap_20"]["trans_mean_m"], "m", "front end alone",
                                    front["relative_gap_20"]["trans_mean_m"], False, "<= 0.10 m"))
                    ours_deg, ref_deg = _heading_vs_icp_deg(result)
                    rows.append(Row("slam", f"heading change between consecutive scans, off ICP's (median), {label}",
                                    ours_deg, "deg", "the reference (GMapping)", ref_deg, False,
                                    "none: the reference's own noise"))
    return rows
