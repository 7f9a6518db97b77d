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


def test_info_storage_fields_as_ros2_bag_info(synthetic_bag: Path) -> None:
    data = json.loads(run("info", "--json", str(synthetic_bag)).stdout)
    storage = synthetic_bag / "synthetic.mcap"
    assert data["storage_id"] == "mcap" and data["bag_size_bytes"] == storage.stat().st_size
    assert data["files"] == [str(storage)] and data["serialization_format"] == "cdr"
    assert data["ros_distro"] == "rosbags" and data["ros_version"] == 2 and data["metadata_version"] == 9
    topics = {t["name"]: t for t in data["topics"]}
    assert topics["/scan"]["serialization_format"] == "cdr" and isinstance(topics["/scan"]["offered_qos_profiles"], list)
    text = run("info", str(synthetic_bag)).stdout
    assert "storage id: mcap" in text and "ROS distro: rosbags" in text and "serialization format: cdr" in text
    assert f"({storage.stat().st_size} bytes)" in text


def test_info_qos_from_mcap_channels_and_results_distro(real_dir: Path, tmp_path: Path) -> None:
    data = json.loads(run("info", "--json", str(real_dir / "nav2_turtlebot.mcap")).stdout)
    assert data["storage_id"] == "mcap" and data["ros_distro"] is None and data["metadata_version"] is None
    topics = {t["name"]: t for t in data["topics"]}
    static, = topics["/tf_static"]["offered_qos_profiles"]
    assert static["durability"] == "transient_local" and static["reliability"] == "reliable" and static["depth"] == 1
    assert static["deadline"] == "infinite"
    assert [p["depth"] for p in topics["/tf"]["offered_qos_profiles"]] == [10, 100, 100]
    import numpy as np
    from bagtools.results import ResultsBag

    with ResultsBag(tmp_path / "results.mcap") as bag:
        bag.tf_static([("base", "laser", np.eye(4))])
    text = run("info", str(tmp_path / "results.mcap")).stdout
    assert "ROS distro: humble" in text and "reliable transient_local keep_last(1)" in text


def test_info_ros1_and_sqlite3_storage(real_dir: Path) -> None:
    ros1 = json.loads(run("info", "--json", str(real_dir / "tf_example.bag")).stdout)
    assert ros1["storage_id"] == "ros1" and ros1["serialization_format"] == "ros1" and ros1["ros_version"] == 1
    assert all("latching" in t for t in ros1["topics"])
    db3 = json.loads(run("info", "--json", str(real_dir / "tf_example")).stdout)
    assert db3["storage_id"] == "sqlite3" and db3["bag_size_bytes"] == (real_dir / "tf_example" / "tf_example.db3").stat().st_size
