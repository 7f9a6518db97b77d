"""Simulator speed: simulated seconds per wall second, default configuration and 640x480 clouds.

Baseline, measured in the same run: the same bag without any ray-cast sensor (route,
controller, odometry, AMCL, IMU, joint states, tf and the writer only, ``--no-cloud`` with the
lidar replaced by constant ranges), i.e. the cost floor of the pipeline around the ray casting.

The CLI row times ``python -m bagtools simulate`` as a subprocess, Python start-up and imports
included (what a user waits for); its baseline is the same bag simulated in this process.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

import bagtools_simulate.pipeline as pipeline
from bench.common import Row, best_time_s
from bagtools_simulate.pipeline import SimConfig, simulate_bag


class _ConstantLidar:
    """A lidar stand-in returning fixed ranges: isolates everything but the ray casting."""

    angle_min_rad, angle_increment_rad, range_min_m, range_max_m, rate_hz = 0.0, 2 * np.pi / 360, 0.12, 3.5, 5.0

    def scan(self, world, pose, rng) -> np.ndarray:
        return np.full(360, 1.0, dtype=np.float32)


def _speed(config: SimConfig, repeat: int) -> float:
    tmp = Path(tempfile.mkdtemp(prefix="bench_simulate_"))
    try:
        wall = best_time_s(lambda: simulate_bag(tmp / "bag", config, force=True), repeat)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return config.duration_s / wall


def _baseline_speed(duration_s: float, repeat: int) -> float:
    original = pipeline.Lidar
    pipeline.Lidar = _ConstantLidar
    try:
        return _speed(SimConfig(duration_s=duration_s, cloud=False), repeat)
    finally:
        pipeline.Lidar = original


def _cli_speed(duration_s: float, repeat: int) -> float:
    """Sim s / wall s of ``python -m bagtools simulate OUT --duration D --force`` (default config), start-up included."""
    tmp = Path(tempfile.mkdtemp(prefix="bench_simulate_cli_"))
    command = [sys.executable, "-m", "bagtools", "simulate", str(tmp / "bag"), "--duration", f"{duration_s:g}", "--force"]
    try:
        wall = best_time_s(lambda: subprocess.run(command, check=True, capture_output=True), repeat)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return duration_s / wall


def run(quick: bool) -> list[Row]:
    """Three rows: default configuration and 640x480 clouds at 2 Hz, each against the sensor-free baseline;
    the default configuration through the CLI, start-up included, against the same bag simulated in process."""
    duration = 10.0 if quick else 60.0
    repeat = 1 if quick else 2
    baseline = _baseline_speed(duration, repeat)
    default = _speed(SimConfig(duration_s=duration), repeat)
    big = _speed(SimConfig(duration_s=duration / 4, cloud_size=(640, 480)), 1)
    cli_duration = 20.0 if quick else 120.0
    in_process = _speed(SimConfig(duration_s=cli_duration), 1 if quick else 3)
    cli = _cli_speed(cli_duration, 1 if quick else 5)
    base = "same pipeline without sensor ray casting"
    return [
        Row("simulate", "default config (lidar + 160x120 cloud at 2 Hz), one core", default, "sim s / wall s", base,
            baseline, True, ">= 50"),
        Row("simulate", "640x480 clouds at 2 Hz, one core", big, "sim s / wall s", base, baseline, True, ""),
        Row("simulate", f"{cli_duration:g} s bag through the CLI, start-up included, one core", cli, "sim s / wall s",
            "same bag simulated in process (no start-up)", in_process, True, ">= 100"),
    ]
