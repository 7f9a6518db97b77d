"""Laser odometry (``bagtools ndt-odom``): speed of the whole pipeline and accuracy against wheel odometry.

Speed: scans per second of NdtOdomPipeline.run() (reading tf, /odom and the
scans, matching every pair, evaluating against the ground truth) on a
simulated lap without clouds, against the bare read + decode of the same scans
(what any consumer of the bag pays at least). Accuracy: APE rmse (evo's
definition, translation, no alignment) of the NDT trajectory and of the wheel
odometry against the ground truth of the same simulated lap with realistic
odometry noise (lower is better).

Real logs (rows skipped when ``../shared/data/real`` is absent): the MIT CSAIL
log with and without wheel odometry (1 m and 20 degrees between scans),
scored per scan step against its /ground_truth (GMapping's estimate), as
``evo_rpe --delta 1 --delta_unit f``. Baselines, same run: the wheel odometry
itself, and (without odometry) NDT from constant velocity with no search.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import time

import numpy as np

from bagtools.io import decode_laserscan, open_bag
from bagtools.commands.ndt_odom import NdtOdomOptions, NdtOdomPipeline, write_ndt_odom
from bagtools.trajectory import rpe_frames
from bench.common import Row, best_time_s
from bagtools_simulate.pipeline import SimConfig, simulate_bag


def _read_decode(bag: Path) -> int:
    n = 0
    with open_bag(bag) as reader:
        for rec in reader.messages(["/scan"]):
            n += len(decode_laserscan(rec.msg).points_xy()) > 0
    return n


REAL = Path(__file__).resolve().parents[2] / "shared" / "data" / "real"


def _per_scan(result, trajectory) -> tuple[float, float, int]:
    trans, rot = rpe_frames(result.ground_truth, trajectory, delta=1)
    return float(trans.mean()), float(rot.mean()), int(np.count_nonzero(trans > 0.2))


def _real_rows() -> list[Row]:
    if not (REAL / "csail_odom").is_dir():
        return []
    rows = []
    t0 = time.perf_counter()
    with_odom = NdtOdomPipeline(REAL / "csail_odom", NdtOdomOptions()).run()
    elapsed = time.perf_counter() - t0
    t_m, r_d, over = _per_scan(with_odom, with_odom.trajectory)
    o_m, o_d, o_over = _per_scan(with_odom, with_odom.odometry)
    cap = "ndt-odom, real CSAIL log with odometry"
    rows += [
        Row(cap, "per-scan error, translation (mean)", t_m, "m", "wheel odometry", o_m, False, "<= 0.03"),
        Row(cap, "per-scan error, rotation (mean)", r_d, "deg", "wheel odometry", o_d, False, "<= 1"),
        Row(cap, "steps over 0.2 m off", over, "steps", "wheel odometry", o_over, False, "0"),
        Row(cap, "whole run, 396 s of data", elapsed, "s", "the bag's duration", 396.0, False, "<= 25 s"),
    ]
    t0 = time.perf_counter()
    no_odom = NdtOdomPipeline(REAL / "csail_scans", NdtOdomOptions()).run()
    elapsed = time.perf_counter() - t0
    plain = NdtOdomPipeline(REAL / "csail_scans", NdtOdomOptions(init="constant-velocity", search=False)).run()
    t_m, r_d, over = _per_scan(no_odom, no_odom.trajectory)
    p_m, p_d, p_over = _per_scan(plain, plain.trajectory)
    cap = "ndt-odom, real CSAIL log without odometry"
    rows += [
        Row(cap, "per-scan error, translation (mean)", t_m, "m", "NDT from constant velocity, no search", p_m, False,
            "<= 0.03"),
        Row(cap, "per-scan error, rotation (mean)", r_d, "deg", "NDT from constant velocity, no search", p_d, False,
            "<= 1"),
        Row(cap, "steps over 0.2 m off", over, "steps", "NDT from constant velocity, no search", p_over, False, "0"),
        Row(cap, "pairs that fell back to their guess", no_odom.summary["fallbacks"], "pairs",
            "NDT from constant velocity, no search", plain.summary["fallbacks"], False, "<= 1% (4)"),
        Row(cap, "whole run, 396 s of data", elapsed, "s", "the bag's duration", 396.0, False, "<= 25 s"),
    ]
    return rows


def run(quick: bool) -> list[Row]:
    """Pipeline scans/s vs read+decode and NDT vs wheel odometry APE on a lap; the real CSAIL rows."""
    duration = 20.0 if quick else 120.0
    repeat = 1 if quick else 3
    with tempfile.TemporaryDirectory(prefix="bench_ndt_odom_") as tmp:
        bag = Path(tmp) / "lap"
        simulate_bag(bag, SimConfig(duration_s=duration, route="lap", odom_noise="realistic", cloud=False, seed=0))
        n_scans = _read_decode(bag)
        decode_s = best_time_s(lambda: _read_decode(bag), repeat)
        results = []
        pipeline_s = best_time_s(lambda: results.append(NdtOdomPipeline(bag, NdtOdomOptions()).run()), repeat)

        def with_files(mcap: bool) -> None:
            result = NdtOdomPipeline(bag, NdtOdomOptions(), keep_scans=mcap).run()
            write_ndt_odom(result, Path(tmp) / "out", force=True, mcap=mcap)

        plain_s = best_time_s(lambda: with_files(False), repeat)
        mcap_s = best_time_s(lambda: with_files(True), repeat)
    summary = results[-1].summary
    ndt_ate = summary["errors_ndt"]["ape_translation_m"]["rmse"]
    odom_ate = summary["errors_odometry"]["ape_translation_m"]["rmse"]
    return [
        Row("ndt-odom", f"whole pipeline on a {duration:g} s simulated lap ({n_scans} scans, 360 beams), one core",
            n_scans / pipeline_s, "scans/s", "read + decode of the same scans", n_scans / decode_s, True, ">= 5 (real time)"),
        Row("ndt-odom", f"APE rmse of NDT on a {duration:g} s lap, realistic odometry noise", ndt_ate, "m",
            "wheel odometry APE rmse", odom_ate, False, "<= 0.5 x odometry"),
        Row("ndt-odom", f"whole run with its files on a {duration:g} s lap, with results.mcap", n_scans / mcap_s,
            "scans/s", "same run with --no-mcap", n_scans / plain_s),
    ] + ([] if quick else _real_rows())
