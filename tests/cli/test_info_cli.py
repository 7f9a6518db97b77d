"""`bagtools info` end to end, through the real console entry point."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest


def run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "bagtools", *args], capture_output=True, text=True, timeout=120)


def test_info_text_and_json(synthetic_bag: Path) -> None:
    text = run("info", str(synthetic_bag))
    assert text.returncode == 0, text.stderr
    assert "/scan" in text.stdout and "sensor_msgs/msg/LaserScan" in text.stdout
    assert "odom\n└── base_link  (dynamic, 10.0 Hz, 100 samples" in text.stdout
    assert "    └── base_scan  (static)" in text.stdout
    data = json.loads(run("info", "--json", str(synthetic_bag)).stdout)
    topics = {t["name"]: t for t in data["topics"]}
    assert topics["/scan"]["count"] == 50
    assert topics["/scan"]["frequency_hz"] == pytest.approx(5.0, rel=1e-6)
    assert data["duration_s"] == pytest.approx(9.902, abs=1e-9)
    frames = {f["child"]: f for f in data["tf_frames"]}
    assert frames["base_link"]["parent"] == "odom" and not frames["base_link"]["is_static"]
    assert frames["base_scan"]["is_static"]


def test_info_real_nav2_bag(real_dir: Path) -> None:
    result = run("info", "--json", str(real_dir / "nav2_turtlebot.mcap"))
    assert result.returncode == 0, result.stderr
    data = json.loads(result.stdout)
    assert {t["name"]: t["count"] for t in data["topics"]} == {"/amcl_pose": 135, "/odom": 2639, "/tf": 5422, "/tf_static": 1}
    frames = {f["child"]: f for f in data["tf_frames"]}
    assert frames["odom"]["parent"] == "map" and frames["base_link"]["parent"] == "odom"
    assert sum(f["is_static"] for f in frames.values()) == 29


@pytest.mark.parametrize("make,problem", [
    (lambda d: d / "missing.mcap", "no such file or directory"),
    (lambda d: (d / "notes.mcap").write_text("not a bag") and d / "notes.mcap", "not a ROS bag"),
    (lambda d: d, "not a rosbag2 bag"),
])
def test_info_bad_input_is_one_line_exit_2(tmp_path: Path, make, problem: str) -> None:
    path = make(tmp_path)
    result = run("info", str(path))
    assert result.returncode == 2
    assert result.stderr.count("\n") == 1 and "Traceback" not in result.stderr
    assert result.stderr.startswith(f"bagtools: {path}: ") and problem in result.stderr


def test_info_truncated_mcap_reports_recovery(tmp_path: Path, real_dir: Path) -> None:
    data = (real_dir / "nav2_turtlebot.mcap").read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: int(len(data) * 0.6)])
    result = run("info", str(cut))
    assert result.returncode == 0
    assert "truncated MCAP" in result.stderr and "recovered" in result.stderr
    assert "/odom" in result.stdout


def test_help_has_an_example() -> None:
    result = run("info", "--help")
    assert result.returncode == 0 and "Example:" in result.stdout and "bagtools info" in result.stdout
