"""`bagtools map-cloud` end to end: files other tools open, and one-line errors."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from bagtools.errors import BagtoolsError

from tests.conftest import make_cloud, write_bag

FIXTURE = Path(__file__).resolve().parents[2] / "fixtures" / "sim_lap_cloud_20s"


def run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "bagtools", "map-cloud", *args], capture_output=True, text=True, timeout=300)


def test_outputs_open_in_open3d(tmp_path: Path) -> None:
    import open3d as o3d

    out = tmp_path / "map"
    result = run(str(FIXTURE), "--out", str(out), "--voxel", "0.02")
    assert result.returncode == 0, result.stderr
    assert sorted(p.name for p in out.iterdir()) == ["cloud_map.pcd", "cloud_map.ply", "cloud_map.png", "results.mcap",
                                                     "summary.json"]
    summary = json.loads((out / "summary.json").read_text())
    pcd = o3d.io.read_point_cloud(str(out / "cloud_map.pcd"))
    ply = o3d.io.read_point_cloud(str(out / "cloud_map.ply"))
    assert len(pcd.points) == len(ply.points) == summary["points_out"] > 0
    assert (out / "cloud_map.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert summary["options"]["voxel_m"] == 0.02 and "accuracy_vs_truth_m" in summary
    assert "distance to true surfaces" in result.stdout


def test_refuses_to_overwrite_without_force(tmp_path: Path) -> None:
    out = tmp_path / "map"
    assert run(str(FIXTURE), "--out", str(out)).returncode == 0
    before = (out / "summary.json").read_bytes()
    again = run(str(FIXTURE), "--out", str(out), "--sample", "0.5")
    assert again.returncode == 2 and "already exists" in again.stderr and again.stderr.count("\n") == 1
    assert (out / "summary.json").read_bytes() == before
    assert run(str(FIXTURE), "--out", str(out), "--sample", "0.5", "--force").returncode == 0
    assert (out / "summary.json").read_bytes() != before


def _bag_without_tf(tmp_path: Path) -> Path:
    cloud = make_cloud(10**18, np.ones((10, 3)))
    return write_bag(tmp_path / "notf", [("/camera/depth/points", "sensor_msgs/msg/PointCloud2", 10**18, cloud)])


@pytest.mark.parametrize("args,problem", [
    (lambda d: [str(FIXTURE), "--topic", "/nope"], "no topic '/nope'"),
    (lambda d: [str(FIXTURE), "--frame", "world"], "frame 'world' is not in the tf tree"),
    (lambda d: [str(d / "missing")], "no such file or directory"),
    (lambda d: [str(_bag_without_tf(d))], "no /tf or /tf_static data"),
    (lambda d: [str(FIXTURE), "--sample", "1.5"], "--sample must be in (0, 1]"),
    (lambda d: [str(FIXTURE), "--max-range", "0.1"], "has a point within --max-range 0.1 m, so there is no map"),
])
def test_bad_input_one_line_exit_2_and_no_output(tmp_path: Path, args, problem: str) -> None:
    out = tmp_path / "out"
    result = run(*args(tmp_path), "--out", str(out))
    assert result.returncode == 2, result.stderr
    assert result.stderr.count("\n") == 1 and "Traceback" not in result.stderr and problem in result.stderr
    assert not out.exists() or list(out.iterdir()) == []


def test_failure_while_writing_leaves_nothing(tmp_path: Path, monkeypatch) -> None:
    from bagtools.commands.map_cloud import CloudMapOptions, CloudMapPipeline, writer

    result = CloudMapPipeline(FIXTURE, CloudMapOptions()).run()

    def broken_png(*args, **kwargs):
        raise OSError("disk full")

    monkeypatch.setattr(writer, "render_map_png", broken_png)
    with pytest.raises(BagtoolsError, match="cannot write: disk full") as err:  # naming the output, not the bag
        writer.write_cloud_map(result, tmp_path / "out")
    assert err.value.path == str(tmp_path / "out")
    assert not (tmp_path / "out").exists()  # the run created it: a failure leaves the file system as it was


def test_help_has_examples() -> None:
    result = run("--help")
    assert result.returncode == 0 and "Example:" in result.stdout and "bagtools map-cloud" in result.stdout


def test_no_cloud_placeable_is_an_error(tmp_path: Path) -> None:
    from tests.conftest import make_tf

    t0 = 10**18
    msgs = [("/tf", "tf2_msgs/msg/TFMessage", t0 + i * 10**8, make_tf(t0 + i * 10**8, "map", "camera", (i, 0, 0), (0, 0, 0, 1)))
            for i in range(5)]
    msgs.append(("/camera/depth/points", "sensor_msgs/msg/PointCloud2", t0 + 5 * 10**9,
                 make_cloud(t0 + 5 * 10**9, np.ones((10, 3)))))
    bag = write_bag(tmp_path / "late", msgs)
    result = run(str(bag), "--out", str(tmp_path / "out"))
    assert result.returncode == 2 and result.stderr.count("\n") == 1
    assert "no cloud on /camera/depth/points could be placed in frame 'map' (1 outside tf data)" in result.stderr


def test_real_scans_without_laser_mount(real_dir: Path, tmp_path: Path) -> None:
    result = run(str(real_dir / "turtlebot3_real_lidar_odom.bag"), "--topic", "/scan", "--frame", "odom",
                 "--sample", "1", "--out", str(tmp_path / "out"))
    assert result.returncode == 0, result.stderr
    assert "no transform from base_link to base_scan in the bag; assuming the scan frame is the base frame" in result.stderr
    assert "dropped 8 corrupt /tf samples odom -> base_link" in result.stderr
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["clouds_used"] >= 289 and summary["points_out"] > 10_000


def test_empty_and_all_nan_clouds_are_counted(tmp_path: Path) -> None:
    from tests.conftest import make_tf

    t0 = 10**18
    msgs = [("/tf", "tf2_msgs/msg/TFMessage", t0 + i * 10**8, make_tf(t0 + i * 10**8, "map", "camera", (0, 0, 0), (0, 0, 0, 1)))
            for i in range(30)]
    msgs.append(("/camera/depth/points", "sensor_msgs/msg/PointCloud2", t0 + 10**9, make_cloud(t0 + 10**9, np.empty((0, 3)))))
    msgs.append(("/camera/depth/points", "sensor_msgs/msg/PointCloud2", t0 + 2 * 10**9,
                 make_cloud(t0 + 2 * 10**9, np.full((4, 3), np.nan))))
    msgs.append(("/camera/depth/points", "sensor_msgs/msg/PointCloud2", t0 + 2 * 10**9 + 1,
                 make_cloud(t0 + 2 * 10**9, np.ones((100, 3)))))
    msgs.sort(key=lambda m: m[2])
    bag = write_bag(tmp_path / "empty", msgs)
    result = run(str(bag), "--out", str(tmp_path / "out"), "--sample", "1")
    assert result.returncode == 0, result.stderr
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["clouds_used"] == 1 and summary["clouds_skipped"] == {"empty cloud": 2}
    assert summary["points_out"] == 100


def _far_tf_bag(tmp_path: Path, where: str, axis: int, value: float) -> Path:
    """The robustness scene (3 s) with every transform of one edge ``value`` metres off on ``axis``."""
    from tests.robustness.scene import make_scene

    scene = make_scene(duration_s=3.0)
    topic, child = {"odom": ("/tf", "base_link"), "map": ("/tf", "odom"), "camera": ("/tf_static", "camera_link")}[where]
    for entry in scene.of(topic):
        for tf in entry.item:
            if tf.child == child:
                xyz = list(tf.xyz)
                xyz[axis] = value
                tf.xyz = tuple(xyz)
    return scene.write(tmp_path / f"far_{where}_{axis}_{value:g}")


@pytest.mark.parametrize("where, axis, value", [
    ("odom", 2, 1e30),      # the side view's rows collapse to one height: matplotlib's singular axes
    ("camera", 2, 1e30),    # the same through a /tf_static mount
    ("odom", 0, 1e300),     # float32 points overflow to inf: a NaN raster size
    ("map", 0, -1e30),      # a localizer's map -> odom
])
@pytest.mark.parametrize("command", ["map-cloud", "grid"])
def test_a_far_off_tf_translation_is_said_not_an_internal_error(tmp_path: Path, capsys, command: str, where: str,
                                                                axis: int, value: float) -> None:
    """A tf translation of 1e30 m on every sample of an edge (too persistent to be a spike) used to end map-cloud in
    the picture and grid in the raster as an internal error: now it is a one-line error or a warning."""
    from bagtools.cli import main

    bag = _far_tf_bag(tmp_path, where, axis, value)
    argv = [command, str(bag), "--out", str(tmp_path / "out")] + (["--topic", "/scan"] if command == "grid" else [])
    with pytest.raises(SystemExit) as exit_info:
        main(argv)
    err = capsys.readouterr().err
    assert "internal error" not in err and "Traceback" not in err, err
    lines = [line for line in err.strip().splitlines() if line]
    assert all(line.startswith("bagtools: ") for line in lines), err
    if exit_info.value.code == 2:
        errors = [line for line in lines if not line.startswith("bagtools: warning: ")]
        assert len(errors) == 1 and str(bag) in errors[0], err
    else:
        assert exit_info.value.code == 0 and any("beyond" in line for line in lines), err
