"""results.mcap of map-cloud, grid and ndt-odom: every message decodes, frames line up, scans land on the map."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from bagtools.transforms import quat2tform, xyzw2quat
from tests.results.test_writer import decode_all

FIXTURE = Path(__file__).resolve().parents[2] / "fixtures" / "sim_lap_cloud_20s"


def _ns(stamp) -> int:
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def _T(transform) -> np.ndarray:
    q, t = transform.rotation, transform.translation
    T = quat2tform(xyzw2quat(np.array([q.x, q.y, q.z, q.w])))
    T[:3, 3] = (t.x, t.y, t.z)
    return T


def _tf_tables(msgs: dict) -> tuple[dict[tuple[str, int], tuple[str, np.ndarray]], dict[str, tuple[str, np.ndarray]]]:
    """(child, stamp) -> (parent, T) of /tf, and child -> (parent, T) of /tf_static."""
    dynamic = {}
    for _, msg in msgs.get("/tf", []):
        for ts in msg.transforms:
            dynamic[(ts.child_frame_id, _ns(ts.header.stamp))] = (ts.header.frame_id, _T(ts.transform))
    static = {}
    for _, msg in msgs.get("/tf_static", []):
        for ts in msg.transforms:
            static[ts.child_frame_id] = (ts.header.frame_id, _T(ts.transform))
    return dynamic, static


def _chain(frame: str, child: str, stamp: int, dynamic: dict, static: dict) -> np.ndarray:
    """T_frame_child through the results' own tf, exactly at ``stamp``."""
    T = np.eye(4)
    while child != frame:
        parent, T_parent_child = static[child] if child in static else dynamic[(child, stamp)]
        T, child = T_parent_child @ T, parent
    return T


def _cloud_xyz(msg) -> np.ndarray:
    data = np.frombuffer(bytes(msg.data), dtype=np.float32).reshape(msg.width, msg.point_step // 4)
    return data[:, :3].astype(np.float64)


def test_map_cloud_results_put_each_cloud_on_the_map(tmp_path: Path) -> None:
    out = tmp_path / "map"
    done = subprocess.run([sys.executable, "-m", "bagtools", "map-cloud", str(FIXTURE), "--out", str(out)],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    msgs = decode_all(out / "results.mcap")
    assert set(msgs) == {"/cloud_map", "/trajectory", "/tf", "/tf_static", "/camera/depth/points"}
    (_, cloud_map), = msgs["/cloud_map"]
    assert cloud_map.header.frame_id == "map"
    dynamic, static = _tf_tables(msgs)
    assert static["map_cloud/camera_depth_optical_frame"][0] == "map_cloud/base_footprint"
    landed = []
    for _, cloud in msgs["/camera/depth/points"]:
        assert cloud.header.frame_id == "map_cloud/camera_depth_optical_frame"
        T = _chain("map", cloud.header.frame_id, _ns(cloud.header.stamp), dynamic, static)
        landed.append(_cloud_xyz(cloud) @ T[:3, :3].T + T[:3, 3])
    landed = np.concatenate(landed)
    mapped = _cloud_xyz(cloud_map)
    assert landed.shape == mapped.shape  # no voxels: the map is exactly the clouds that went in
    assert np.allclose(landed[np.lexsort(landed.T)], mapped[np.lexsort(mapped.T)], atol=1e-4)
    assert len(msgs["/trajectory"][0][1].poses) == len(msgs["/camera/depth/points"])


def test_grid_results_map_is_what_map_server_loads(tmp_path: Path) -> None:
    from bagtools.grid import read_nav2_map
    from bagtools.commands.grid import GridMapOptions, GridMapPipeline, write_grid_map

    result = GridMapPipeline(FIXTURE, GridMapOptions(), keep_scans=True).run()
    write_grid_map(result, tmp_path / "grid")
    msgs = decode_all(tmp_path / "grid" / "results.mcap")
    assert set(msgs) == {"/map", "/trajectory", "/tf", "/tf_static", "/scan"}
    (_, occ), = msgs["/map"]
    nav2 = read_nav2_map(tmp_path / "grid" / "map.yaml")
    data = np.asarray(occ.data, dtype=np.int8).reshape(occ.info.height, occ.info.width)
    assert np.array_equal(data, np.flipud(nav2.occupancy))
    assert (occ.info.origin.position.x, occ.info.origin.position.y) == pytest.approx(nav2.origin[:2])
    assert occ.info.resolution == pytest.approx(nav2.resolution_m)
    scans = msgs["/scan"]
    assert len(scans) == result.summary["scans_used"] == len(msgs["/tf"])
    dynamic, static = _tf_tables(msgs)
    assert static["grid/base_scan"][0] == "grid/base_footprint"
    assert {s.header.frame_id for _, s in scans} == {"grid/base_scan"}
    positions = np.array([_chain("map", "grid/base_scan", _ns(s.header.stamp), dynamic, static)[:2, 3]
                          for _, s in scans])
    assert np.allclose(positions, result.scan_path_xy, atol=1e-9)  # each scan where the grid inserted it


def test_ndt_odom_results_hold_the_trajectories(tmp_path: Path) -> None:
    from bagtools.commands.ndt_odom import NdtOdomOptions, NdtOdomPipeline, write_ndt_odom
    from bagtools.trajectory import read_tum

    result = NdtOdomPipeline(FIXTURE, NdtOdomOptions(), keep_scans=True).run()
    write_ndt_odom(result, tmp_path / "ndt")
    msgs = decode_all(tmp_path / "ndt" / "results.mcap")
    assert set(msgs) == {"/trajectory", "/odometry", "/ground_truth", "/tf", "/tf_static", "/scan", "/cloud_map"}
    tum = read_tum(tmp_path / "ndt" / "trajectory.tum")
    (_, path), = msgs["/trajectory"]
    assert path.header.frame_id == "odom" and len(path.poses) == len(tum) == len(msgs["/scan"])
    xy = np.array([[p.pose.position.x, p.pose.position.y] for p in path.poses])
    assert np.allclose(xy, tum.positions[:, :2], atol=1e-8)
    dynamic, static = _tf_tables(msgs)
    stamp = _ns(msgs["/scan"][50][1].header.stamp)
    assert np.allclose(_chain("odom", "ndt_odom/base_footprint", stamp, dynamic, static), result.trajectory.poses[50])
    assert len(msgs["/ground_truth"][0][1].poses) > 0 and msgs["/cloud_map"][0][1].width > 300


def test_no_mcap_skips_it_and_leaves_an_earlier_one_alone(tmp_path: Path) -> None:
    """--force replaces only what the run itself writes: a run without results.mcap neither needs --force for an
    earlier one nor deletes it (the developers' guide; it was deleted)."""
    out = tmp_path / "grid"
    run = [sys.executable, "-m", "bagtools", "grid", str(FIXTURE), "--out", str(out)]
    assert subprocess.run(run, capture_output=True, timeout=300).returncode == 0
    earlier = (out / "results.mcap").read_bytes()
    again = subprocess.run(run + ["--no-mcap"], capture_output=True, text=True, timeout=300)
    assert again.returncode == 2 and "map.pgm: already exists" in again.stderr  # the run's own outputs need --force
    forced = subprocess.run(run + ["--no-mcap", "--force"], capture_output=True, text=True, timeout=300)
    assert forced.returncode == 0, forced.stderr
    assert (out / "results.mcap").read_bytes() == earlier and (out / "map.yaml").is_file()


@pytest.mark.parametrize("command", ["grid", "map-cloud", "ndt-odom", "slam"])
def test_results_beside_their_bag_give_no_frame_two_parents(command: str, tmp_path: Path) -> None:
    """The bag and its results.mcap read as one stream (as Foxglove shows them, as `ros2 bag play` plays them):
    every frame has one parent. The estimates' frames are namespaced; the roots (map, odom) are shared."""
    from rosbags.highlevel import AnyReader

    out = tmp_path / command
    done = subprocess.run([sys.executable, "-m", "bagtools", command, str(FIXTURE), "--out", str(out)],
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    bag = FIXTURE / next(p.name for p in FIXTURE.iterdir() if p.suffix == ".mcap")
    parents: dict[str, set[str]] = {}
    with AnyReader([bag, out / "results.mcap"]) as reader:
        conns = [c for c in reader.connections if c.topic in ("/tf", "/tf_static")]
        for conn, _, raw in reader.messages(connections=conns):
            for ts in reader.deserialize(raw, conn.msgtype).transforms:
                parents.setdefault(ts.child_frame_id, set()).add(ts.header.frame_id)
    assert {f for f in parents if f.startswith(f"{command.replace('-', '_')}/")}, parents  # the results' own frames
    assert {f: p for f, p in parents.items() if len(p) > 1} == {}


def test_slam_results_hang_the_bags_odom_under_the_slam_map(tmp_path: Path, real_dir: Path) -> None:
    """The CSAIL bag's tf is odom -> base_link with odom a root: slam_map -> odom at each scan joins the two trees
    (before, slam/base_link hung under slam_map, which nothing tied to the bag's odom)."""
    from rosbags.highlevel import AnyReader

    bag = real_dir / "csail_odom"
    out = tmp_path / "slam"
    done = subprocess.run([sys.executable, "-m", "bagtools", "slam", str(bag), "--out", str(out)], capture_output=True,
                          text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    parents: dict[str, set[str]] = {}
    stamps = []
    for path in (bag, out / "results.mcap"):
        with AnyReader([path]) as reader:
            conns = [c for c in reader.connections if c.topic in ("/tf", "/tf_static")]
            for conn, _, raw in reader.messages(connections=conns):
                for t in reader.deserialize(raw, conn.msgtype).transforms:
                    parents.setdefault(t.child_frame_id, set()).add(t.header.frame_id)
                    if t.child_frame_id == "odom":
                        stamps.append(t.header.stamp.sec * 10**9 + t.header.stamp.nanosec)
    assert all(len(p) == 1 for p in parents.values()), parents
    assert parents["odom"] == {"slam_map"} and parents["slam/base_link"] == {"slam_map"}
    roots = {p for ps in parents.values() for p in ps} - set(parents)
    assert roots == {"slam_map"}  # one tree
    assert len(stamps) == 406  # at each scan
