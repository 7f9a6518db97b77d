"""``bagtools ndt-odom`` end to end: outputs, messages and exit status."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np

from tests.conftest import FIXTURES, make_scan, write_bag

T0_NS = 1_700_000_000_000_000_000


def _run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "bagtools", *args], capture_output=True, text=True)


def test_help_has_an_example() -> None:
    out = _run("ndt-odom", "--help")
    assert out.returncode == 0 and "Example:" in out.stdout and "bagtools ndt-odom out/sim --out out/ndt" in out.stdout


def test_simulated_bag_writes_everything_and_refuses_to_overwrite(tmp_path: Path) -> None:
    out_dir = tmp_path / "ndt"
    done = _run("ndt-odom", str(FIXTURES / "sim_lap_cloud_20s"), "--out", str(out_dir))
    assert done.returncode == 0, done.stderr
    assert "101 scans: 100 pairs matched" in done.stdout and "NDT: APE rmse" in done.stdout
    assert "odometry: APE rmse" in done.stdout
    names = sorted(p.name for p in out_dir.iterdir())
    assert names == ["ground_truth.tum", "odometry.tum", "results.mcap", "scan_map.png", "summary.json", "trajectory.png",
                     "trajectory.tum"]
    summary = json.loads((out_dir / "summary.json").read_text())
    assert summary["errors_ndt"]["ape_translation_m"]["rmse"] < summary["errors_odometry"]["ape_translation_m"]["rmse"]
    again = _run("ndt-odom", str(FIXTURES / "sim_lap_cloud_20s"), "--out", str(out_dir))
    assert again.returncode == 2 and "already exists (use --force to overwrite)" in again.stderr
    assert "Traceback" not in again.stderr
    forced = _run("ndt-odom", str(FIXTURES / "sim_lap_cloud_20s"), "--out", str(out_dir), "--force",
                  "--reference", "previous", "--init", "constant-velocity", "--cell-size", "1.0")
    assert forced.returncode == 0, forced.stderr
    assert json.loads((out_dir / "summary.json").read_text())["options"]["cell_size_m"] == 1.0


def test_missing_bag_and_missing_topic_exit_2(tmp_path: Path) -> None:
    missing = _run("ndt-odom", str(tmp_path / "nope"), "--out", str(tmp_path / "o"))
    assert missing.returncode == 2 and missing.stderr.strip() == f"bagtools: {tmp_path / 'nope'}: no such file or directory"
    wrong = _run("ndt-odom", str(FIXTURES / "sim_lap_cloud_20s"), "--out", str(tmp_path / "o"), "--topic", "/front")
    assert wrong.returncode == 2
    assert "no topic '/front' in the bag (LaserScan topics: /scan; choose one with --topic)" in wrong.stderr
    assert not (tmp_path / "o").exists()


def test_all_invalid_scans_exit_2_and_write_nothing(tmp_path: Path) -> None:
    msgs = [("/scan", "sensor_msgs/msg/LaserScan", T0_NS + i, make_scan(T0_NS + i, np.full(360, np.nan))) for i in range(3)]
    bag = write_bag(tmp_path / "blind", msgs)
    done = _run("ndt-odom", str(bag), "--out", str(tmp_path / "o"))
    assert done.returncode == 2 and "Traceback" not in done.stderr
    assert f"bagtools: {bag}: no usable scan on /scan: every scan was skipped (3 fewer than 5 valid ranges)" in done.stderr
    assert not (tmp_path / "o").exists() or not any((tmp_path / "o").iterdir())


def test_bad_option_values_exit_2(tmp_path: Path) -> None:
    bag = str(FIXTURES / "sim_lap_cloud_20s")
    offset = _run("ndt-odom", bag, "--out", str(tmp_path / "o"), "--scan-frame-offset", "1,2")
    assert offset.returncode == 2 and "expected X,Y,YAW" in offset.stderr
    score = _run("ndt-odom", bag, "--out", str(tmp_path / "o"), "--min-score", "3")
    assert score.returncode == 2 and "--min-score must be in [0, 1]" in score.stderr and "Traceback" not in score.stderr
