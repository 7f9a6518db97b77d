"""Laser odometry: accuracy on simulated laps, evo agreement, real scans, 180-degree lasers, bad input."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from evo.core import metrics, sync
from evo.tools import file_interface

from bagtools.errors import BagtoolsError
from bagtools.commands.ndt_odom import NdtOdomOptions, NdtOdomPipeline, write_ndt_odom
from bagtools.trajectory import read_tum
from bagtools.transforms import pose2tform
from bagtools_simulate.pipeline import SimConfig, simulate_bag
from bagtools_simulate.sensors.lidar import Lidar
from tests.conftest import FIXTURES
from tests.ndt_odom.conftest import T0_NS, make_odometry, make_scan, make_tf, scan_bag, write_bag

SCAN = "sensor_msgs/msg/LaserScan"


@pytest.fixture(scope="module")
def lap_bag(tmp_path_factory) -> Path:
    """A 60 s lap (about one round of the TurtleBot3 world) with realistic wheel odometry noise."""
    path = tmp_path_factory.mktemp("lap") / "lap60"
    simulate_bag(path, SimConfig(duration_s=60.0, route="lap", odom_noise="realistic", cloud=False, seed=1))
    return path


@pytest.fixture(scope="module")
def lap_run(lap_bag: Path, tmp_path_factory) -> tuple[dict, Path]:
    result = NdtOdomPipeline(lap_bag, NdtOdomOptions()).run()
    out = tmp_path_factory.mktemp("lap_out")
    write_ndt_odom(result, out)
    return result.summary, out


def test_lap_ndt_error_at_most_half_of_odometry(lap_run) -> None:
    summary, _ = lap_run
    ndt = summary["errors_ndt"]["ape_translation_m"]["rmse"]
    odom = summary["errors_odometry"]["ape_translation_m"]["rmse"]
    assert summary["init"] == "auto" and summary["odometry_used"] and summary["reference"] == "keyframe"
    assert summary["fallbacks"] == 0 and summary["pairs_matched"] == summary["scans_used"] - 1 == 300
    assert summary["searched"] <= 3 and summary["odometry_rejected"] == 0 and summary["warnings"] == []
    assert ndt <= 0.5 * odom, (ndt, odom)
    assert summary["errors_ndt"]["rpe_translation_m_per_1m"]["rmse"] < 0.02


def test_lap_previous_reference_runs_and_stays_bounded(lap_bag: Path) -> None:
    summary = NdtOdomPipeline(lap_bag, NdtOdomOptions(reference="previous")).run().summary
    assert summary["reference"] == "previous" and summary["fallbacks"] == 0
    assert summary["errors_ndt"]["ape_translation_m"]["rmse"] < 0.2


def test_outputs_and_summary_equal_evo(lap_run) -> None:
    summary, out = lap_run
    assert sorted(p.name for p in out.iterdir()) == ["ground_truth.tum", "odometry.tum", "results.mcap", "scan_map.png",
                                                     "summary.json", "trajectory.png", "trajectory.tum"]
    assert json.loads((out / "summary.json").read_text()) == json.loads(json.dumps(summary))
    ref = file_interface.read_tum_trajectory_file(str(out / "ground_truth.tum"))
    for name, tum in (("ndt", "trajectory.tum"), ("odometry", "odometry.tum")):
        est = file_interface.read_tum_trajectory_file(str(out / tum))
        r, e = sync.associate_trajectories(ref, est, max_diff=0.01)
        ape = metrics.APE(metrics.PoseRelation.translation_part)
        ape.process_data((r, e))
        rpe = metrics.RPE(metrics.PoseRelation.translation_part, delta=1.0, delta_unit=metrics.Unit.meters)
        rpe.process_data((r, e))
        for key, metric in (("ape_translation_m", ape), ("rpe_translation_m_per_1m", rpe)):
            theirs = metric.get_all_statistics()
            ours = summary[f"errors_{name}"][key]
            for stat in ("rmse", "mean", "median", "max", "std"):
                assert ours[stat] == pytest.approx(theirs[stat], rel=1e-6, abs=1e-9), (name, key, stat)


def test_trajectory_starts_at_odometry_pose_and_is_the_base_frame(lap_run) -> None:
    _, out = lap_run
    ndt, odom, truth = (read_tum(out / n) for n in ("trajectory.tum", "odometry.tum", "ground_truth.tum"))
    np.testing.assert_allclose(ndt.poses[0], odom.poses[0], atol=1e-8)
    np.testing.assert_array_equal(ndt.stamps_ns, odom.stamps_ns)
    first = np.searchsorted(truth.stamps_ns, ndt.stamps_ns[0])
    np.testing.assert_allclose(truth.poses[first], ndt.poses[0], atol=1e-6)
    # the base frame (not the laser, 6.4 cm behind it) follows the truth
    at = np.searchsorted(truth.stamps_ns, ndt.stamps_ns)
    assert np.median(np.linalg.norm(truth.positions[at] - ndt.positions, axis=1)) < 0.05


def test_fixture_bag_with_constant_velocity_and_zero_init() -> None:
    bag = FIXTURES / "sim_lap_cloud_20s"
    for init in ("constant-velocity", "zero"):
        summary = NdtOdomPipeline(bag, NdtOdomOptions(init=init)).run().summary
        assert summary["init"] == init and summary["scans_used"] == 101
        assert summary["errors_ndt"]["ape_translation_m"]["rmse"] < 0.1, init


def test_180_degree_laser_without_odometry(tmp_path: Path, lap_truth) -> None:
    stamps, T_map_base = lap_truth
    lidar = Lidar(samples=181, angle_min_rad=-np.pi / 2, angle_max_rad=np.pi / 2)
    bag = scan_bag(tmp_path / "half", stamps[::6], T_map_base[::6], lidar)
    result = NdtOdomPipeline(bag, NdtOdomOptions()).run()
    s = result.summary
    assert s["init"] == "auto" and not s["odometry_used"] and s["odometry_source"] is None and result.odometry is None
    np.testing.assert_allclose(result.trajectory.poses[0], np.eye(4), atol=1e-12)
    assert s["base_frame"] == "base_scan" and s["scans_used"] == 101
    assert s["errors_ndt"]["ape_translation_m"]["rmse"] < 0.1
    assert "errors_odometry" not in s
    with pytest.raises(BagtoolsError, match="--init odom needs wheel odometry"):
        NdtOdomPipeline(bag, NdtOdomOptions(init="odom")).run()


def test_real_turtlebot3_bag(real_dir: Path) -> None:
    result = NdtOdomPipeline(real_dir / "turtlebot3_real_lidar_odom.bag", NdtOdomOptions()).run()
    s = result.summary
    assert s["scans_used"] == 291 and s["base_frame"] == "base_link" and s["odometry_used"]
    assert any("no transform from base_link to base_scan in the bag; assuming the scan frame is the base frame" in w
               for w in s["warnings"])
    assert any("dropped 8 corrupt /tf samples odom -> base_link" in w for w in s["warnings"])
    assert s["fallbacks"] <= 10
    # the robot stays in its small arena: NDT and (glitch-free) odometry agree within a metre
    assert np.abs(result.trajectory.positions).max() < 2.0
    assert np.abs(result.odometry.positions).max() < 2.0
    offset = NdtOdomPipeline(real_dir / "turtlebot3_real_lidar_odom.bag",
                             NdtOdomOptions(scan_frame_offset=(-0.05, 0.0, 0.0))).run().summary
    assert not any("no transform" in w for w in offset["warnings"])
    assert offset["T_base_scan_xyz_yaw"] == [-0.05, 0.0, 0.0, 0.0]


# -- bad input ---------------------------------------------------------------------


def _room_scan(stamp_ns: int, x_m: float = 0.0) -> object:
    """A scan from (x_m, 0) inside a 4 m x 3 m box (origin at its centre), 360 beams."""
    angles = np.arange(360) * np.pi / 180
    c, s = np.cos(angles), np.sin(angles)
    with np.errstate(divide="ignore"):
        to_x = np.where(c > 0, (2.0 - x_m) / c, np.where(c < 0, (-2.0 - x_m) / c, np.inf))
        to_y = np.where(s != 0, 1.5 / np.abs(s), np.inf)
    return make_scan(stamp_ns, np.minimum(to_x, to_y))


def test_no_scan_topic(tmp_path: Path) -> None:
    bag = write_bag(tmp_path / "tf_only", [("/tf", "tf2_msgs/msg/TFMessage", T0_NS,
                                            make_tf(T0_NS, "odom", "base_link", (0, 0, 0), (0, 0, 0, 1)))])
    with pytest.raises(BagtoolsError, match="no topic '/scan' in the bag \\(the bag has no LaserScan topic\\)"):
        NdtOdomPipeline(bag, NdtOdomOptions()).run()
    other = write_bag(tmp_path / "other", [("/front/scan", SCAN, T0_NS, _room_scan(T0_NS))])
    with pytest.raises(BagtoolsError, match="LaserScan topics: /front/scan; choose one with --topic"):
        NdtOdomPipeline(other, NdtOdomOptions()).run()


def test_all_ranges_invalid_writes_the_summary(tmp_path: Path) -> None:
    msgs = [("/scan", SCAN, T0_NS + i * 200_000_000, make_scan(T0_NS + i * 200_000_000, np.full(360, np.inf)))
            for i in range(5)]
    result = NdtOdomPipeline(write_bag(tmp_path / "blind", msgs), NdtOdomOptions()).run()
    assert result.problem is not None and "no usable scan on /scan" in result.problem
    assert result.summary["scans_skipped"] == {"fewer than 5 valid ranges": 5}
    written = write_ndt_odom(result, tmp_path / "out")
    assert [p.name for p in written] == ["summary.json"]
    assert json.loads((tmp_path / "out" / "summary.json").read_text())["scans_used"] == 0


def test_single_scan_writes_a_one_pose_trajectory(tmp_path: Path) -> None:
    bag = write_bag(tmp_path / "one", [("/scan", SCAN, T0_NS, _room_scan(T0_NS))])
    result = NdtOdomPipeline(bag, NdtOdomOptions()).run()
    assert result.problem is None and len(result.trajectory) == 1
    assert result.summary["pairs_matched"] == 0 and any("only one usable scan" in w for w in result.summary["warnings"])
    names = [p.name for p in write_ndt_odom(result, tmp_path / "out")]
    assert names == ["trajectory.tum", "trajectory.png", "scan_map.png", "results.mcap", "summary.json"]
    assert len(read_tum(tmp_path / "out" / "trajectory.tum")) == 1


def test_time_going_backwards_is_skipped_and_counted(tmp_path: Path) -> None:
    stamps = T0_NS + np.array([0, 200, 400, 300, 600, 600, 800]) * 1_000_000
    msgs = [("/scan", SCAN, T0_NS + i * 200_000_000, _room_scan(int(t), 0.05 * i)) for i, t in enumerate(stamps)]
    result = NdtOdomPipeline(write_bag(tmp_path / "back", msgs), NdtOdomOptions()).run()
    s = result.summary
    assert s["scans_skipped"] == {"stamp not after the previous scan": 2} and s["scans_used"] == 5
    assert any("time going backwards" in w and "2 scan(s)" in w for w in s["warnings"])
    np.testing.assert_array_equal(result.trajectory.stamps_ns, stamps[[0, 1, 2, 4, 6]])


def test_poor_match_falls_back_to_the_odometry_guess(tmp_path: Path) -> None:
    msgs = []
    for i in range(4):
        t = T0_NS + i * 200_000_000
        msgs.append(("/odom", "nav_msgs/msg/Odometry", t, make_odometry(t, "odom", "base_link", pose2tform([0.1 * i, 0, 0]))))
        ranges = np.full(360, np.inf)
        if i != 2:
            ranges = _room_scan(t, 0.1 * i).ranges
        else:  # a few scattered returns that cannot be matched
            ranges[::40] = 0.5 + np.arange(9) * 0.3
        msgs.append(("/scan", SCAN, t + 1, make_scan(t, ranges)))
    result = NdtOdomPipeline(write_bag(tmp_path / "poor", msgs), NdtOdomOptions(min_score=0.3)).run()
    s = result.summary
    assert s["odometry_source"] == "/odom (odom -> base_link)" and s["odometry_used"]
    assert s["fallbacks"] >= 1 and s["pairs_matched"] + s["fallbacks"] == 3
    np.testing.assert_allclose(result.trajectory.positions[:, 0], [0.0, 0.1, 0.2, 0.3], atol=0.02)


def test_bad_options_are_one_line_errors() -> None:
    for kwargs, text in (({"cell_size_m": 0.0}, "--cell-size"), ({"min_score": 2.0}, "--min-score"),
                         ({"init": "gps"}, "--init"), ({"reference": "map"}, "--reference")):
        with pytest.raises(BagtoolsError, match=text):
            NdtOdomOptions(**kwargs)


def test_without_odometry_the_trajectory_is_the_base_where_tf_static_mounts_the_laser(tmp_path: Path,
                                                                                       lap_truth) -> None:
    """No odom -> base transform, but /tf_static base_link -> base_scan: the poses are base_link's, not the laser's."""
    from bagtools.transforms import se2_between, tform2pose
    from bagtools_simulate.world import load_world

    stamps, T_map_base = lap_truth
    mount = np.array([0.3, 0.1, 0.4])  # x, y, yaw of the laser on the base: far enough off to show
    T_base_scan = pose2tform(mount)
    world, lidar, rng = load_world("turtlebot3_world"), Lidar(), np.random.default_rng(0)
    quat_xyzw = (0.0, 0.0, np.sin(mount[2] / 2), np.cos(mount[2] / 2))
    msgs = [("/tf_static", "tf2_msgs/msg/TFMessage", int(stamps[0]) - 1,
             make_tf(int(stamps[0]) - 1, "base_link", "base_scan", (mount[0], mount[1], 0.1), quat_xyzw))]
    for stamp, T in zip(stamps[::3], T_map_base[::3]):
        x, y, yaw = tform2pose(T @ T_base_scan)
        msgs.append(("/scan", SCAN, int(stamp), make_scan(int(stamp), lidar.scan(world, (x, y, 0.2, yaw), rng),
                                                           lidar.angle_min_rad, lidar.angle_increment_rad)))
    bag = write_bag(tmp_path / "mounted", msgs)
    result = NdtOdomPipeline(bag, NdtOdomOptions()).run()
    s = result.summary
    assert s["base_frame"] == "base_link" and s["scan_frame"] == "base_scan" and not s["odometry_used"]
    np.testing.assert_allclose(s["T_base_scan_xyz_yaw"], [0.3, 0.1, 0.1, 0.4], atol=1e-9)
    est = tform2pose(result.trajectory.poses).reshape(-1, 3)
    truth = tform2pose(T_map_base[::3]).reshape(-1, 3)
    err = se2_between(se2_between(truth[0], truth), se2_between(est[0], est))
    assert np.hypot(err[:, 0], err[:, 1]).max() < 0.05  # the laser's own path would be off by up to 0.6 m
    write_ndt_odom(result, tmp_path / "out")
    assert (tmp_path / "out" / "trajectory.tum").read_text().splitlines()[0].endswith("body: base_link")


def test_scans_that_never_change_while_the_wheels_drive_are_said(tmp_path: Path) -> None:
    """A laser driver that froze repeats its last scan: 47 identical scans while the odometry drives 4.6 m. The
    matches say the robot stood still; the run says why its trajectory disagrees with the wheels."""
    rng = np.random.default_rng(0)
    ranges = (2.0 + 0.5 * rng.random(360)).astype(np.float32)
    msgs = []
    for i in range(48):
        t = T0_NS + i * 200_000_000
        T = np.eye(4)
        T[0, 3] = 0.1 * i
        msgs.append(("/odom", "nav_msgs/msg/Odometry", t, make_odometry(t, "odom", "base_scan", T)))
        msgs.append(("/scan", SCAN, t + 1, make_scan(t, ranges)))
    bag = write_bag(tmp_path / "frozen", msgs)
    s = NdtOdomPipeline(bag, NdtOdomOptions()).run().summary
    assert s["scans_repeated"] == 47
    assert any("47 scan(s) on /scan repeat the scan before them exactly while the odometry moves 4.70 m" in w
               for w in s["warnings"]), s["warnings"]


def test_a_live_laser_repeats_no_scan(lap_run) -> None:
    summary, _ = lap_run
    assert summary["scans_repeated"] == 0 and not any("repeat the scan" in w for w in summary["warnings"])


def test_returns_beyond_100_m_are_not_matched(tmp_path: Path) -> None:
    """Returns at 450-500 m sized the search's raster past its limit (an internal error): they are left out of the
    matching, and a scan with nothing nearer is skipped and counted; a bag of only such scans is a one-line error."""
    rng = np.random.default_rng(0)
    msgs = []
    for i in range(10):
        t = T0_NS + i * 200_000_000
        ranges = (450 + 50 * rng.random(360)).astype(np.float32)
        scan = make_scan(t, ranges)
        scan.range_max = 900.0
        msgs.append(("/scan", SCAN, t + 1, scan))
    bag = write_bag(tmp_path / "far", msgs)
    result = NdtOdomPipeline(bag, NdtOdomOptions()).run()
    assert result.problem is not None and "every scan was skipped (10 fewer than 5 returns within 100 m)" in result.problem
