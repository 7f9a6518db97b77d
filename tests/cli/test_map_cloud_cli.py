"""`bagtools map-cloud` end to end: files other tools open, and one-line errors."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from tests.conftest import make_cloud, write_bag

FIXTURE = Path(__file__).resolve().parents[2] / "fixtures" / "sim_lap_cloud_20s"


def run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "bagtools", "map-cloud", *args], capture_output=True, text=True, timeout=300)


def test_outputs_open_in_open3d(tmp_path: Path) -> None:
    import open3d as o3d

    out = tmp_path / "map"
    result = run(str(FIXTURE), "--out", str(out), "--voxel", "0.02")
    assert result.returncode == 0, result.stderr
    assert sorted(p.name for p in out.iterdir()) == ["cloud_map.pcd", "cloud_map.ply", "cloud_map.png", "summary.json"]
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
])
def test_bad_input_one_line_exit_2_and_no_output(tmp_path: Path, args, problem: str) -> None:
    out = tmp_path / "out"
    result = run(*args(tmp_path), "--out", str(out))
    assert result.returncode == 2, result.stderr
    assert result.stderr.count("\n") == 1 and "Traceback" not in result.stderr and problem in result.stderr
    assert not out.exists() or list(out.iterdir()) == []


def test_failure_while_writing_leaves_nothing(tmp_path: Path, monkeypatch) -> None:
    from bagtools.cloudmap import CloudMapOptions, CloudMapPipeline, writer

    result = CloudMapPipeline(FIXTURE, CloudMapOptions()).run()

    def broken_png(*args, **kwargs):
        raise OSError("disk full")

    monkeypatch.setattr(writer, "render_map_png", broken_png)
    with pytest.raises(OSError):
        writer.write_cloud_map(result, tmp_path / "out")
    assert list((tmp_path / "out").iterdir()) == []


def test_help_has_examples() -> None:
    result = run("--help")
    assert result.returncode == 0 and "Example:" in result.stdout and "bagtools map-cloud" in result.stdout
