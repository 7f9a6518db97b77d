"""The grid-mapping pipeline: accuracy on simulated bags per pose source, scan semantics, limits, real bag."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from bagtools.errors import BagtoolsError
from bagtools.dataset import NO_SCAN_TRANSFORM_WARNING
from bagtools.commands.grid import GridMapOptions, GridMapPipeline
from bagtools.io import open_bag
from bagtools.simtruth import anchor_frame_in_map, read_ground_truth
from bagtools.trajectory import Trajectory, write_tum
from bagtools.transforms import pose2tform
from tests.conftest import FIXTURES, make_scan, make_tf, write_bag

S = 1_000_000_000
T0 = 1_700_000_000 * S
X0, Y0 = 1.013, 2.017


@pytest.fixture(scope="module")
def lap_bag(tmp_path_factory) -> Path:
    """40 s lap of the TurtleBot3 world with realistic odometry noise, no depth camera (~0.3 s to simulate)."""
    from bagtools_simulate.pipeline import SimConfig, simulate_bag

    out = tmp_path_factory.mktemp("grid") / "lap40"
    return simulate_bag(out, SimConfig(duration_s=40.0, seed=3, route="lap", odom_noise="realistic", cloud=False)).path


@pytest.fixture(scope="module")
def truth_result(lap_bag: Path):
    return GridMapPipeline(lap_bag, GridMapOptions(poses="ground-truth")).run()


def test_ground_truth_poses_score_near_perfect(truth_result) -> None:
    acc = truth_result.summary["accuracy_vs_truth"]
    # measured: precision 1.000, recall 0.999, free share 1.000, no phantom obstacles
    assert acc["occupied_precision"] >= 0.99
    assert acc["occupied_recall"] >= 0.98
    assert acc["free_share"] >= 0.99
    assert acc["free_marked_occupied"] <= 0.001
    assert acc["true_occupied_cells"] > 500 and acc["true_free_cells"] > 5000
    s = truth_result.summary
    assert s["scans_used"] == s["scans_total"] == 201 and s["scans_skipped"] == {}
    assert s["base_frame"] == "base_footprint" and s["scan_frames"] == ["base_scan"]
    assert s["max_range_m"] == [3.5] and s["grid"]["cell_size_m"] == 0.05


def test_odometry_frame_scores_worse(lap_bag: Path, truth_result) -> None:
    odom = GridMapPipeline(lap_bag, GridMapOptions(frame="odom")).run().summary
    acc, best = odom["accuracy_vs_truth"], truth_result.summary["accuracy_vs_truth"]
    # measured: precision 0.751, recall 0.738, free share 0.963 (drift smears the walls)
    assert acc["occupied_precision"] < best["occupied_precision"] - 0.1
    assert acc["occupied_recall"] < best["occupied_recall"] - 0.1
    assert acc["free_share"] < best["free_share"]
    assert odom["truth_anchor"]["frame"] == "odom" and odom["truth_anchor"]["robot_frame"] == "base_footprint"


def test_tf_poses_in_map_skip_scans_before_the_localizer(lap_bag: Path) -> None:
    summary = GridMapPipeline(lap_bag, GridMapOptions()).run().summary
    # map -> odom is first stamped 1 s into the bag: the first 5 scans (5 Hz) have no pose in map
    assert summary["scans_skipped"] == {"before pose data": 5}
    assert summary["scans_used"] == 196
    assert summary["accuracy_vs_truth"]["occupied_recall"] >= 0.9


def test_tum_trajectory_of_the_ground_truth_gives_the_same_map(lap_bag: Path, truth_result, tmp_path: Path) -> None:
    with open_bag(lap_bag) as bag:
        stamps, T_map_base, _ = read_ground_truth(bag)
    tum = write_tum(tmp_path / "truth.tum", Trajectory(stamps, T_map_base))
    result = GridMapPipeline(lap_bag, GridMapOptions(poses=str(tum))).run()
    assert result.summary["base_frame"] == "base_footprint"
    assert result.grid.grid_size == truth_result.grid.grid_size
    np.testing.assert_array_equal(result.grid.grid_location_in_world, truth_result.grid.grid_location_in_world)
    np.testing.assert_array_equal(result.grid.occupancy_matrix("ternary"), truth_result.grid.occupancy_matrix("ternary"))
    np.testing.assert_allclose(result.grid.log_odds, truth_result.grid.log_odds, atol=1e-5)


def test_fixture_bag_with_humble_messages(tmp_path: Path) -> None:
    result = GridMapPipeline(FIXTURES / "sim_random_nocloud_20s", GridMapOptions(poses="ground-truth")).run()
    acc = result.summary["accuracy_vs_truth"]
    assert acc["occupied_precision"] >= 0.99 and acc["occupied_recall"] >= 0.9 and acc["free_share"] >= 0.99
    assert result.scan_path_xy.shape == (101, 2)


# ---- scan semantics on synthetic bags ------------------------------------------------------------


def _box_bag(path: Path, ranges_fn, scan_frame_rotation_xyzw=(0, 0, 0, 1), n_scans: int = 5, with_tf: bool = True,
             scan_frame: str = "base_scan") -> Path:
    """The robot standing at (X0, Y0) in odom, yaw 0 (off the cell edges); scans from ``ranges_fn(angles)`` in ``scan_frame``."""
    angles = np.arange(360) * np.pi / 180
    msgs = []
    if with_tf:
        msgs.append(("/tf_static", "tf2_msgs/msg/TFMessage", T0,
                     make_tf(T0, "base_link", "base_scan", (0.0, 0.0, 0.1), scan_frame_rotation_xyzw)))
        for i in range(11):
            t = T0 + i * S // 5
            msgs.append(("/tf", "tf2_msgs/msg/TFMessage", t, make_tf(t, "odom", "base_link", (X0, Y0, 0), (0, 0, 0, 1))))
    for i in range(n_scans):
        t = T0 + (i + 1) * S // 5
        scan = make_scan(t, ranges_fn(angles))
        scan.header.frame_id = scan_frame
        msgs.append(("/scan", "sensor_msgs/msg/LaserScan", t, scan))
    msgs.sort(key=lambda m: m[2])
    return write_bag(path, msgs)


def _square_ranges(angles: np.ndarray, half: float = 1.0) -> np.ndarray:
    """Ranges from the centre of a square room of half-width ``half`` metres, scan frame axis-aligned."""
    c, s = np.abs(np.cos(angles)), np.abs(np.sin(angles))
    with np.errstate(divide="ignore"):
        return np.minimum(np.where(c > 0, half / c, np.inf), np.where(s > 0, half / s, np.inf)).astype(np.float32)


def test_scanner_mounted_upside_down_maps_like_an_upright_one(tmp_path: Path) -> None:
    """A scan frame rolled by pi sees the world mirrored: beam angle a points to -a."""
    def upright_ranges(a: np.ndarray) -> np.ndarray:
        """A room turned by 0.3 rad, and an obstacle at half the distance ahead (+x): no symmetry."""
        return _square_ranges(a + 0.3) * np.where(np.cos(a) > 0.9, 0.5, 1.0).astype(np.float32)

    upright = _box_bag(tmp_path / "up", upright_ranges)
    flipped = _box_bag(tmp_path / "flip", lambda a: upright_ranges(-a), scan_frame_rotation_xyzw=(1.0, 0.0, 0.0, 0.0))
    a = GridMapPipeline(upright, GridMapOptions(frame="odom")).run().grid
    b = GridMapPipeline(flipped, GridMapOptions(frame="odom")).run().grid
    assert a.grid_size == b.grid_size
    np.testing.assert_array_equal(a.occupancy_matrix("ternary"), b.occupancy_matrix("ternary"))
    ahead = 0.5 / math.cos(0.3)  # the short return straight ahead of the robot
    np.testing.assert_array_equal(b.check_occupancy(np.array([[X0 + ahead, Y0], [X0 + ahead - 0.1, Y0]])), [1, 0])


def test_range_conventions(tmp_path: Path) -> None:
    """NaN and below-range_min values are ignored, +inf clears free space to the maximum range."""
    def ranges(a: np.ndarray) -> np.ndarray:
        r = np.full(a.size, 1.0, dtype=np.float32)
        r[(a > 0.5) & (a < 1.0)] = np.nan           # erroneous: no update
        r[(a > 2.0) & (a < 2.5)] = 0.0               # below range_min (0.12): no update
        r[(a > 3.0) & (a < 3.5)] = np.inf            # no return: free up to range_max 3.5
        return r

    result = GridMapPipeline(_box_bag(tmp_path / "r", ranges), GridMapOptions(frame="odom")).run()
    grid = result.grid

    def at(angle: float, dist: float) -> int:
        return int(grid.check_occupancy(np.array([[X0 + dist * math.cos(angle), Y0 + dist * math.sin(angle)]]))[0])

    assert at(0.0, 1.02) == 1 and at(0.0, 0.5) == 0          # ordinary return: wall at 1 m, free before
    assert at(0.75, 0.5) == -1 and at(0.75, 1.02) == -1      # NaN beams: unknown
    assert at(2.25, 0.5) == -1                                # zero range: unknown, not a wall at the sensor
    assert at(3.25, 3.0) == 0 and at(3.25, 1.02) == 0         # inf: free far beyond the 1 m walls
    s = result.summary
    assert s["scans_used"] == 5 and s["returns_used"] < s["beams_used"]

    limited = GridMapPipeline(_box_bag(tmp_path / "r2", ranges), GridMapOptions(frame="odom", max_range_m=1.5)).run()
    assert limited.summary["max_range_m"] == [1.5]
    grid = limited.grid
    assert at(0.0, 1.02) == 1                                 # returns within --max-range still hit
    assert at(3.25, 1.4) == 0 and at(3.25, 1.6) == -1         # inf clears only up to --max-range


def test_nothing_to_map_raises(tmp_path: Path) -> None:
    nan_bag = _box_bag(tmp_path / "nan", lambda a: np.full(a.size, np.nan, dtype=np.float32))
    with pytest.raises(BagtoolsError, match=r"none of the 5 scans on /scan could be used .*5 no valid ranges"):
        GridMapPipeline(nan_bag, GridMapOptions(frame="odom")).run()
    inf_bag = _box_bag(tmp_path / "inf", lambda a: np.full(a.size, np.inf, dtype=np.float32))
    with pytest.raises(BagtoolsError, match="no scan on /scan has a return within its range limits"):
        GridMapPipeline(inf_bag, GridMapOptions(frame="odom")).run()


def test_grid_cell_limit(tmp_path: Path) -> None:
    bag = _box_bag(tmp_path / "b", _square_ranges)
    with pytest.raises(BagtoolsError, match=r"more than the limit of 1e\+03"):
        GridMapPipeline(bag, GridMapOptions(frame="odom", max_cells=1000)).run()


def test_scan_frame_missing_from_tf_is_taken_as_the_base(tmp_path: Path) -> None:
    bag = _box_bag(tmp_path / "b", _square_ranges, scan_frame="laser")
    result = GridMapPipeline(bag, GridMapOptions(frame="odom")).run()
    assert result.summary["base_frame"] == "base_link"
    assert NO_SCAN_TRANSFORM_WARNING.format(base="base_link", scan_frame="laser") in result.summary["warnings"]
    np.testing.assert_allclose(result.scan_path_xy, [[X0, Y0]] * 5)


def test_real_turtlebot3_bag_in_odom(real_dir: Path) -> None:
    bag = real_dir / "turtlebot3_real_lidar_odom.bag"
    result = GridMapPipeline(bag, GridMapOptions(frame="odom")).run()
    s = result.summary
    assert NO_SCAN_TRANSFORM_WARNING.format(base="base_link", scan_frame="base_scan") in s["warnings"]
    assert any("dropped 8 corrupt /tf samples odom -> base_link" in w for w in s["warnings"])
    assert s["scans_used"] >= 290 and s["max_range_m"] == [3.0]
    # a small room: walls within a few metres, and far more free cells than occupied ones
    assert 100 < s["grid"]["occupied_cells"] < s["grid"]["free_cells"]
    assert result.grid.grid_size[0] * result.grid.grid_size[1] < 200 * 200
    assert "accuracy_vs_truth" not in s


def test_anchor_frame_in_map() -> None:
    T_map_odom = pose2tform(np.array([1.0, -2.0, 0.7]))
    T_odom_base = pose2tform(np.array([[0.5, 0.1, 0.2], [0.9, 0.3, 0.4], [1.3, 0.6, 0.5]]))
    T_map_base = T_map_odom @ T_odom_base
    T_map_base[2] = pose2tform(np.array([9.0, 9.0, 0.0]))   # truth and odom disagree later on (drift)
    valid = np.array([False, True, True])
    T, first = anchor_frame_in_map(T_map_base, T_odom_base, valid)
    assert first == 1
    np.testing.assert_allclose(T, T_map_odom, atol=1e-12)
    assert anchor_frame_in_map(T_map_base, T_odom_base, np.zeros(3, dtype=bool)) is None


def test_unusable_range_max_needs_max_range(tmp_path: Path) -> None:
    msgs = [("/tf", "tf2_msgs/msg/TFMessage", T0 + i * S, make_tf(T0 + i * S, "odom", "base_scan", (0, 0, 0), (0, 0, 0, 1)))
            for i in range(3)]
    scan = make_scan(T0 + S, np.full(360, 1.0, dtype=np.float32))
    scan.range_max = 0.0
    bag = write_bag(tmp_path / "b", sorted(msgs + [("/scan", "sensor_msgs/msg/LaserScan", T0 + S, scan)], key=lambda m: m[2]))
    with pytest.raises(BagtoolsError, match=r"\(1 range_max not positive \(give --max-range\)\)"):
        GridMapPipeline(bag, GridMapOptions(frame="odom")).run()
    result = GridMapPipeline(bag, GridMapOptions(frame="odom", max_range_m=2.0)).run()
    assert result.summary["max_range_m"] == [2.0] and result.summary["scans_used"] == 1


def test_tf_repairs_are_said_only_when_tf_places_the_scans(real_dir: Path) -> None:
    """The real TurtleBot3 bag's /tf has corrupt samples and glitches. Mapped at tf's poses the run says what it
    dropped; mapped at poses given to it (slam's optimized trajectory, here the laser odometry's) it does not use
    those samples, and says nothing of them (slam's front end has said what its own reading of tf found)."""
    from bagtools.commands.ndt_odom import run_front_end

    bag = real_dir / "turtlebot3_real_lidar_odom.bag"
    by_tf = GridMapPipeline(bag, GridMapOptions(frame="odom")).run().summary["warnings"]
    assert any("corrupt /tf samples odom -> base_link" in w for w in by_tf)
    given = GridMapPipeline(bag, GridMapOptions(frame="odom", poses="laser odometry"),
                            trajectory=run_front_end(bag).trajectory).run().summary["warnings"]
    assert not any("odom -> base_link" in w and ("corrupt" in w or "glitch" in w) for w in given), given
