"""Laser odometry (``bagtools ndt-odom``): speed of the whole pipeline and accuracy against wheel odometry.

Speed: scans per second of NdtOdomPipeline.run() (reading tf, /odom and the
scans, matching every pair, evaluating against the ground truth) on a
simulated lap without clouds, against the bare read + decode of the same scans
(what any consumer of the bag pays at least). Accuracy: APE rmse (evo's
definition, translation, no alignment) of the NDT trajectory and of the wheel
odometry against the ground truth of the same simulated lap with realistic
odometry noise (lower is better).
"""

from __future__ import annotations

import tempfile
from pathlib import Path

from bagtools.io import decode_laserscan, open_bag
from bagtools.ndtodom import NdtOdomOptions, NdtOdomPipeline
from bench.common import Row, best_time_s
from simulate.pipeline import SimConfig, simulate_bag


def _read_decode(bag: Path) -> int:
    n = 0
    with open_bag(bag) as reader:
        for rec in reader.messages(["/scan"]):
            n += len(decode_laserscan(rec.msg).points_xy()) > 0
    return n


def run(quick: bool) -> list[Row]:
    """Two rows: pipeline scans/s vs read+decode, and NDT vs wheel odometry APE on a lap."""
    duration = 20.0 if quick else 120.0
    repeat = 1 if quick else 3
    with tempfile.TemporaryDirectory(prefix="bench_ndt_odom_") as tmp:
        bag = Path(tmp) / "lap"
        simulate_bag(bag, SimConfig(duration_s=duration, route="lap", odom_noise="realistic", cloud=False, seed=0))
        n_scans = _read_decode(bag)
        decode_s = best_time_s(lambda: _read_decode(bag), repeat)
        results = []
        pipeline_s = best_time_s(lambda: results.append(NdtOdomPipeline(bag, NdtOdomOptions()).run()), repeat)
    summary = results[-1].summary
    ndt_ate = summary["errors_ndt"]["ape_translation_m"]["rmse"]
    odom_ate = summary["errors_odometry"]["ape_translation_m"]["rmse"]
    return [
        Row("ndt-odom", f"whole pipeline on a {duration:g} s simulated lap ({n_scans} scans, 360 beams), one core",
            n_scans / pipeline_s, "scans/s", "read + decode of the same scans", n_scans / decode_s, True, ">= 5 (real time)"),
        Row("ndt-odom", f"APE rmse of NDT on a {duration:g} s lap, realistic odometry noise", ndt_ate, "m",
            "wheel odometry APE rmse", odom_ate, False, "<= 0.5 x odometry"),
    ]
