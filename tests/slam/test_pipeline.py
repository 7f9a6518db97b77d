"""The SLAM pipeline over a front-end run: accuracy, every output, and bad input.

The front end is the stand-in of :mod:`tests.standin` (ground truth with a
laser odometry's drift), so these tests measure the back end alone.
"""

from __future__ import annotations

import json
from pathlib import Path

import gtsam
import numpy as np
import pytest

from bagtools.errors import BagtoolsError, TopicError
from bagtools.grid import read_nav2_map
from bagtools.odometry.steps import FrontEndRun
from bagtools.pose_graph import build_pose_graph
from bagtools.commands.slam import SLAM_FILES, SlamOptions, SlamPipeline, SlamResult, write_slam
from bagtools.trajectory.evaluate import align_se2
from bagtools.pose_graph.loops import LoopOutcome
from bagtools.trajectory import read_tum
from bagtools.transforms import pose2tform, se2_between
from tests.conftest import FIXTURES, make_scan, write_bag
from tests.ndt_odom.conftest import scan_bag
from bagtools_simulate.sensors.lidar import Lidar
from tests.standin import CSAIL_DRIFT, Drift, as_front_end_result, front_end_from_truth, true_poses_at_scans

T0_NS = 1_700_000_000_000_000_000


def _recorded(front: FrontEndRun, with_truth: bool = True):
    return lambda bag, options: as_front_end_result(bag, front, with_truth)


@pytest.fixture(scope="module")
def figure8_slam(figure8_bag: Path, tmp_path_factory) -> tuple[SlamResult, Path]:
    """SLAM of the long figure eight with the real front end (laser odometry of bagtools.commands.ndt_odom)."""
    result = SlamPipeline(figure8_bag, SlamOptions()).run()
    out = tmp_path_factory.mktemp("slam_out")
    write_slam(result, out)
    return result, out


def test_figure8_two_centimetres_and_the_map_matches_the_world(figure8_slam) -> None:
    s = figure8_slam[0].summary
    slam, front = s["errors_slam"], s["errors_front_end"]
    assert slam["ape_aligned_m"]["rmse"] <= 0.02 and slam["ape_translation_m"]["rmse"] <= 0.02
    assert slam["ape_aligned_m"]["rmse"] <= front["ape_aligned_m"]["rmse"]
    assert slam["relative_gap_20"]["trans_mean_m"] <= 0.02
    loops = s["loop_closure"]
    assert loops["accepted"] >= 20 and loops["accepted"] + loops["rejected"] == loops["candidates"]
    assert s["graph"]["loop_edges"] == loops["accepted"] and s["graph"]["odometry_edges"] == s["keyframes"] - 1
    accuracy = s["map"]["accuracy_vs_truth"]
    assert accuracy["occupied_precision"] >= 0.95 and accuracy["occupied_recall"] >= 0.95, accuracy
    assert s["optimization"]["runs"] >= 1 and s["optimization"]["final_error"] >= 0
    assert s["front_end"]["odometry_used"] and s["front_end"]["base_frame"] == "base_footprint"


def test_figure8_stand_in_drift_is_removed(figure8_bag: Path, figure8_front: FrontEndRun) -> None:
    """The back end alone against a front end that drifts more than the real one (1 % scale, 0.17 deg/m)."""
    back = build_pose_graph(figure8_front.steps)
    _, truth = true_poses_at_scans(figure8_bag)
    truth = truth[back.keyframe_steps]

    def aligned_rmse(poses: np.ndarray) -> float:
        R, t = align_se2(poses[:, :2], truth[:, :2])
        return float(np.sqrt(np.mean(np.sum((poses[:, :2] @ R.T + t - truth[:, :2]) ** 2, axis=1))))

    before, after = aligned_rmse(figure8_front.poses()[back.keyframe_steps]), aligned_rmse(back.graph.poses)
    assert before > 0.04 and after < 0.02, (before, after)


def test_outputs_are_complete_and_readable(figure8_slam) -> None:
    result, out = figure8_slam
    s = result.summary
    assert sorted(p.name for p in out.iterdir()) == sorted(SLAM_FILES)
    trajectory, odometry = read_tum(out / "trajectory.tum"), read_tum(out / "odometry.tum")
    assert len(trajectory) == len(odometry) == s["scans"] == s["front_end"]["scans_used"]
    assert np.allclose(odometry.positions, result.odometry.positions, atol=1e-6)
    assert np.allclose(trajectory.poses[0], odometry.poses[0], atol=1e-4)  # both start at the first scan's pose
    truth = read_tum(out / "ground_truth.tum")
    assert np.allclose(truth.positions[0], trajectory.positions[0], atol=0.02)
    factors, values = gtsam.readG2o(str(out / "pose_graph.g2o"), False)
    assert values.size() == s["keyframes"] and factors.size() == s["graph"]["odometry_edges"] + s["graph"]["loop_edges"]
    key = int(result.back_end.keyframe_steps[-1])
    last = values.atPose2(s["keyframes"] - 1)
    assert np.allclose([last.x(), last.y()], trajectory.positions[key, :2], atol=1e-4)
    nav2 = read_nav2_map(out / "map.yaml")
    assert np.isclose(nav2.resolution_m, 0.05) and (nav2.ternary() == 1).sum() > 100
    assert (out / "map.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    written = json.loads((out / "summary.json").read_text())
    assert written["loop_closure"]["accepted"] == s["loop_closure"]["accepted"]
    assert set(written["timing_s"]) >= {"front_end", "back_end", "map", "total"}
    # every setting the run used, as run: the NDT cell the scans chose, the loop search's window and gates
    settings = written["settings"]
    assert settings["front_end"]["cell_size_m"] == s["front_end"]["cell_size_m"]
    assert settings["loop_closure"]["search_radius_m"] == 5.0 and settings["loop_closure"]["min_score"] == 0.5
    assert settings["back_end"]["loop_kernel"] == "huber"


def test_without_loop_closure_the_trajectory_is_the_front_end(figure8_bag: Path, figure8_front: FrontEndRun) -> None:
    back = build_pose_graph(figure8_front.steps, SlamOptions(loop_closure=False).back_end_options())
    assert not back.candidates and not back.graph.loop_indexes()
    keyframes = figure8_front.poses()[back.keyframe_steps]
    d = se2_between(keyframes, back.graph.poses)
    assert np.abs(d).max() < 1e-6


def test_real_csail_log_loops_are_right(csail_odom: Path) -> None:
    front = front_end_from_truth(csail_odom, drift=CSAIL_DRIFT)
    back = build_pose_graph(front.steps, SlamOptions().back_end_options())
    _, truth = true_poses_at_scans(csail_odom)
    truth = truth[back.keyframe_steps]

    def aligned_rmse(poses: np.ndarray) -> float:
        R, t = align_se2(poses[:, :2], truth[:, :2])
        return float(np.sqrt(np.mean(np.sum((poses[:, :2] @ R.T + t - truth[:, :2]) ** 2, axis=1))))

    before, after = aligned_rmse(front.poses()[back.keyframe_steps]), aligned_rmse(back.graph.poses)
    assert before > 2.0 and after < 0.3, (before, after)
    accepted = [c for c in back.candidates if c.status == LoopOutcome.ACCEPTED]
    assert len(accepted) >= 100
    errors = [np.hypot(*se2_between(se2_between(truth[c.old], truth[c.new]), c.T_old_new)[:2]) for c in accepted]
    # no look-alike (a corridor's aliases lie a metre and more away); most within a few centimetres
    assert max(errors) < 0.5 and np.median(errors) < 0.06 and np.percentile(errors, 90) < 0.1



def test_real_csail_log_loops_that_correct_a_heading_bias_are_kept(csail_odom: Path) -> None:
    """The odometry's covariances do not know its bias (0.57 degrees per metre here), so the loops that correct
    it keep large residuals: dropping each as an outlier left the map 11 m off (aligned RMSE). A loop that
    another loop from other scans agrees with is kept: 2.5 m. Of the loops kept, nearly all are right."""
    drift = Drift(scale=0.01, heading_bias_rad_per_m=0.01, noise_m=0.01, noise_rad=0.004)
    front = front_end_from_truth(csail_odom, drift=drift)
    back = build_pose_graph(front.steps, SlamOptions().back_end_options())
    _, truth = true_poses_at_scans(csail_odom)
    truth = truth[back.keyframe_steps]
    R, t = align_se2(back.graph.poses[:, :2], truth[:, :2])
    rmse = float(np.sqrt(np.mean(np.sum((back.graph.poses[:, :2] @ R.T + t - truth[:, :2]) ** 2, axis=1))))
    assert rmse < 4.0, rmse
    loops = [c for c in back.graph.constraints if c.kind == "loop"]
    errors = np.array([np.hypot(*se2_between(se2_between(truth[c.i], truth[c.j]), c.T_i_j)[:2]) for c in loops])
    assert len(loops) >= 60 and np.median(errors) < 0.06 and (errors > 0.3).sum() <= 2, errors


def test_real_csail_log_without_odometry_is_consistent(csail_odom: Path) -> None:
    """Issue target on the scans alone (the real front end, the real loop closure): aligned APE at most 0.3 m
    against GMapping's trajectory over the 380 m path. It is 0.092 m; 0.114 m when a wide loop window was
    searched once per 4 m of path (too few for a second match to confirm the first)."""
    bag = csail_odom.parent / "csail_scans"
    if not bag.is_dir():
        pytest.skip(f"real bag not available: {bag}")
    result = SlamPipeline(bag, SlamOptions()).run()
    errors = result.summary["errors_slam"]
    assert errors["ape_aligned_m"]["rmse"] < 0.105, errors["ape_aligned_m"]
    # the target is a mean of 0.1 m; GMapping's own glitches at scans 42 and 364 weigh about a centimetre of it
    assert errors["relative_gap_20"]["trans_median_m"] < 0.09, errors["relative_gap_20"]
    assert errors["relative_gap_20"]["trans_mean_m"] < 0.115, errors["relative_gap_20"]


# -- bad input ----------------------------------------------------------------------------------


def _never(bag, options):
    raise AssertionError("the front end must not run")


def test_missing_topic_is_refused_before_the_front_end() -> None:
    with pytest.raises(TopicError, match="no topic '/laser'.*LaserScan topics: /scan"):
        SlamPipeline(FIXTURES / "sim_random_nocloud_20s", SlamOptions(topic="/laser"), front_end=_never).run()
    with pytest.raises(TopicError, match="not|type"):
        SlamPipeline(FIXTURES / "sim_random_nocloud_20s", SlamOptions(topic="/odom"), front_end=_never).run()


def test_no_usable_scan_is_one_error(tmp_path: Path) -> None:
    ranges = np.full(360, np.nan, dtype=np.float32)
    bag = write_bag(tmp_path / "nan", [("/scan", "sensor_msgs/msg/LaserScan", T0_NS + i * 200_000_000,
                                        make_scan(T0_NS + i * 200_000_000, ranges)) for i in range(5)])
    with pytest.raises(BagtoolsError, match="no usable scan on /scan"):
        SlamPipeline(bag, SlamOptions()).run()


def test_bag_without_ground_truth_has_no_errors(tmp_path: Path, figure8_bag: Path, figure8_front: FrontEndRun) -> None:
    steps = figure8_front.steps[:200]
    stamps, truth = true_poses_at_scans(figure8_bag)
    bag = scan_bag(tmp_path / "no_truth", stamps[:200], pose2tform(truth[:200]), Lidar(), with_truth=False)
    result = SlamPipeline(bag, SlamOptions(topic="/scan"), front_end=_recorded(FrontEndRun(steps), False)).run()
    assert result.ground_truth is None and "errors_slam" not in result.summary
    write_slam(result, tmp_path / "out")
    assert not (tmp_path / "out" / "ground_truth.tum").exists() and (tmp_path / "out" / "trajectory.tum").exists()


@pytest.mark.parametrize("kwargs,message", [
    ({"resolution_m": 0.0}, "--resolution"), ({"resolution_m": 50.0}, "--resolution"),
    ({"max_range_m": -1.0}, "--max-range"), ({"loop_search_radius_m": float("inf")}, "--loop-search-radius"),
    ({"loop_min_score": 2.0}, "--loop-min-score"), ({"topic": ""}, "--topic"),
])
def test_bad_options_are_one_line_errors(kwargs: dict, message: str) -> None:
    with pytest.raises(BagtoolsError, match=message):
        SlamOptions(**kwargs)


@pytest.mark.parametrize("first", [5, 13])
def test_real_csail_log_without_odometry_from_later_first_scans(csail_odom: Path, csail_restarted, first: int) -> None:
    """Started a few scans later, the scans-only front end meets the sharp turns of scans 52-66 at other speeds
    and keyframes (from these starts it took the turn into scan 67 27 degrees wrong, and SLAM ended 1.3-1.5 m off,
    before the fine grid decided such contests): SLAM's map is as right as from the first scan."""
    bag = csail_odom.parent / "csail_scans"
    result = SlamPipeline(bag, SlamOptions(use_odometry=False), front_end=_recorded(csail_restarted(first))).run()
    assert result.summary["errors_slam"]["ape_aligned_m"]["rmse"] < 0.15, result.summary["errors_slam"]["ape_aligned_m"]


def test_a_laser_without_its_mount_in_tf_is_said_once_and_takes_scan_frame_offset(real_dir: Path) -> None:
    """The real TurtleBot3 bag has no base_link -> base_scan transform: the run says so once, with the option that
    sets it (slam's own); given that option, the front end and the map both use it, and nothing is said."""
    bag = real_dir / "turtlebot3_real_lidar_odom.bag"
    said = SlamPipeline(bag, SlamOptions(loop_closure=False)).run().summary["warnings"]
    missing = [w for w in said if "no transform from base_link to base_scan" in w]
    assert len(missing) == 1 and "--scan-frame-offset" in missing[0], said
    given = SlamPipeline(bag, SlamOptions(loop_closure=False, scan_frame_offset=(-0.064, 0.0, 0.0))).run()
    assert not any("no transform from" in w for w in given.summary["warnings"]), given.summary["warnings"]
    assert given.summary["keyframes"] > 10
