"""The test suite's cost (#44): CPU seconds (user + sys of pytest and its workers) of the suite as `make test` runs
it (one pytest-xdist worker per core, OpenBLAS on one thread in each), against the same suite with OpenBLAS's
default threads, in the same run. Target: at most 600 CPU s on the reference machine (the figure is scaled by the
developers' guide's calibration loop, whose time on this machine the row prints). ``--quick`` runs
tests/odometry and tests/io only.
"""

from __future__ import annotations

import os
import resource
import subprocess
import sys
from pathlib import Path

from bench.bench_slam_unseen import REFERENCE_CALIBRATION_S, calibration_s
from bench.common import Row

REPO = Path(__file__).resolve().parents[1]


def _suite_cpu_s(one_thread: bool, paths: list[str]) -> float:
    """CPU seconds of ``pytest -q -n auto PATHS`` (all of tests/ when empty) in a child process and its workers."""
    env = {k: v for k, v in os.environ.items() if k not in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS")}
    if one_thread:
        env["OPENBLAS_NUM_THREADS"] = "1"
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    subprocess.run([sys.executable, "-m", "pytest", "-q", "-n", "auto", "-p", "no:cacheprovider", *paths],
                   cwd=REPO, env=env, check=True, stdout=subprocess.DEVNULL)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def run(quick: bool) -> list[Row]:
    paths = ["tests/odometry", "tests/io"] if quick else []
    scale = REFERENCE_CALIBRATION_S / calibration_s()
    one = _suite_cpu_s(True, paths) * scale
    default = _suite_cpu_s(False, paths) * scale
    what = "tests/odometry + tests/io" if quick else "make test"
    return [Row("tests", f"{what}, CPU s (user + sys, all workers), scaled to the reference machine", one, "CPU s",
                "the same with OpenBLAS's default threads", default, False,
                "<= 600 CPU s (full suite)")]
