"""map-cloud --refine: depth clouds registered to the map so far (Open3D ICP) on a simulated bag whose odometry drifts."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from bagtools.commands.map_cloud import CloudMapOptions, CloudMapPipeline, write_cloud_map
from bagtools.errors import BagtoolsError
from bagtools.trajectory import read_tum
from bagtools_simulate.pipeline import SimConfig, simulate_bag


@pytest.fixture(scope="module")
def drifting_lap(tmp_path_factory) -> Path:
    """Three minutes of laps with high odometry noise: the walls of the second lap land beside the first's in odom."""
    path = tmp_path_factory.mktemp("refine") / "bag"
    simulate_bag(path, SimConfig(duration_s=180.0, odom_noise="high"))
    return path


def test_refined_clouds_make_a_sharper_map_in_odom(drifting_lap: Path, tmp_path: Path) -> None:
    """Against the true surfaces: the long tail of the drifted map (p95) shrinks by more than half, and the median
    does not grow; the refined poses are written as a TUM file, one per cloud, readable by eval."""
    plain = CloudMapPipeline(drifting_lap, CloudMapOptions(frame="odom", sample=0.1)).run()
    refined = CloudMapPipeline(drifting_lap, CloudMapOptions(frame="odom", refine=True)).run()
    before, after = plain.summary["accuracy_vs_truth_m"], refined.summary["accuracy_vs_truth_m"]
    assert refined.summary["sample_fraction"] == 0.1
    assert after["p95"] < 0.5 * before["p95"], (before, after)
    assert after["median"] <= before["median"], (before, after)
    counts = refined.summary["refined"]
    assert counts["clouds_registered"] >= 0.95 * refined.summary["clouds_used"], counts
    write_cloud_map(refined, tmp_path / "out", mcap=False)
    trajectory = read_tum(tmp_path / "out" / "trajectory.tum")
    assert len(trajectory) == refined.summary["clouds_used"]
    assert (tmp_path / "out" / "trajectory.tum").read_text().startswith("# frame: odom body: base_footprint")
    # without --refine there is no trajectory to write
    write_cloud_map(plain, tmp_path / "plain", mcap=False)
    assert not (tmp_path / "plain" / "trajectory.tum").exists()


def test_refine_refuses_laser_scans(drifting_lap: Path) -> None:
    """Scans lie in one plane, where ICP to planes cannot move them: said, not a map identical to the unrefined."""
    with pytest.raises(BagtoolsError, match="--refine registers 3D clouds"):
        CloudMapPipeline(drifting_lap, CloudMapOptions(frame="odom", topic="/scan", refine=True)).run()


def test_the_map_keeps_the_first_point_of_each_voxel() -> None:
    """A later pass does not overwrite the first: its points join only where the map holds none."""
    from bagtools.commands.map_cloud.refine import CloudRefiner

    refiner = CloudRefiner()
    rng = np.random.default_rng(0)
    wall = np.c_[np.full(400, 2.0), rng.uniform(-1, 1, 400), rng.uniform(0, 1, 400)]
    refiner._add(refiner._cloud(wall, None), np.eye(4))
    first = refiner.points.copy()
    shifted = np.eye(4)
    shifted[0, 3] = 0.01  # within the same voxels
    refiner._add(refiner._cloud(wall, None), shifted)
    assert len(refiner.points) <= len(first) + 40 and np.array_equal(refiner.points[:len(first)], first)


@pytest.mark.parametrize("coloured", [False, True])
def test_a_cloud_tf_misplaces_is_registered_back_onto_the_map(coloured: bool) -> None:
    """A corner of three walls seen twice from the same place while tf says the sensor moved 6 cm: ICP (coloured
    when the points carry rgb) puts the second cloud back where the first one is."""
    from bagtools.commands.map_cloud.refine import CloudRefiner

    rng = np.random.default_rng(0)
    n = 3000
    points = np.vstack([np.c_[rng.uniform(0, 2, n), rng.uniform(0, 2, n), np.zeros(n)],
                        np.c_[np.zeros(n), rng.uniform(0, 2, n), rng.uniform(0, 2, n)],
                        np.c_[rng.uniform(0, 2, n), np.zeros(n), rng.uniform(0, 2, n)]])
    rgb = (np.c_[np.sin(7 * points[:, 0]), np.cos(5 * points[:, 1]), np.sin(3 * points[:, 2])] * 127 + 128).astype(
        np.uint8) if coloured else None
    refiner = CloudRefiner()
    refiner.refine(points, np.eye(4), rgb)
    moved = np.eye(4)
    moved[:3, 3] = [0.05, -0.03, 0.02]
    pose = refiner.refine(points, moved, rgb)
    assert refiner.registered == 1 and np.linalg.norm(pose[:3, 3]) < 0.005, pose[:3, 3]
    assert np.allclose(refiner.correction[:3, 3], -moved[:3, 3], atol=0.005)


def test_the_map_finds_a_clouds_reach_in_its_cubes_as_a_full_scan_would() -> None:
    """The map's points within a box come from the cubes around it (a cloud's cost does not grow with the map),
    in map order: the same rows a scan of every point finds, for a box inside the map and one far larger."""
    from bagtools.commands.map_cloud.refine import CloudRefiner

    refiner = CloudRefiner()
    rng = np.random.default_rng(1)
    for k in range(30):  # clouds along a 15 m corridor, each added where the map holds no point yet
        cloud = np.c_[rng.uniform(0, 1.5, 300) + 0.5 * k, rng.uniform(-1.5, 1.5, 300), rng.uniform(0, 2, 300)]
        refiner._add(refiner._cloud(cloud, None), np.eye(4))
    points = refiner.points
    for lo, hi in (([3.2, -0.4, 0.1], [5.9, 1.1, 1.3]), ([-50.0, -50.0, -50.0], [80.0, 50.0, 50.0])):
        lo, hi = np.array(lo), np.array(hi)
        rows = refiner._rows_near(lo, hi)
        rows = rows[np.all((points[rows] >= lo) & (points[rows] <= hi), axis=1)]
        np.testing.assert_array_equal(rows, np.flatnonzero(np.all((points >= lo) & (points <= hi), axis=1)))
    assert len(refiner.normals) == len(points) > 1000 and refiner.colors is None


def test_a_refinement_gives_the_same_pose_every_time() -> None:
    """Open3D sums ICP's correspondences on TBB threads in an order that changes from run to run (the map's last
    digits did): the refiner runs it on one thread, so the same clouds give the same pose to the bit."""
    from bagtools.commands.map_cloud.refine import CloudRefiner

    rng = np.random.default_rng(3)
    floor = np.c_[rng.uniform(0, 4, 6000), rng.uniform(-2, 2, 6000), np.zeros(6000)]
    wall = np.c_[np.full(4000, 4.0), rng.uniform(-2, 2, 4000), rng.uniform(0, 2, 4000)]
    side = np.c_[rng.uniform(0, 4, 4000), np.full(4000, 2.0), rng.uniform(0, 2, 4000)]
    scene = np.vstack([floor, wall, side])
    moved = np.eye(4)
    moved[:3, 3] = [0.06, -0.04, 0.02]
    noisy = scene + rng.normal(0, 0.005, scene.shape)
    poses = set()
    for _ in range(6):
        refiner = CloudRefiner()
        refiner.refine(scene, np.eye(4))
        poses.add(refiner.refine(noisy, moved).tobytes())
    assert len(poses) == 1
