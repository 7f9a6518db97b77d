"""Robot motion: collision-free routes, controller limits, exact kinematics, odometry drift, AMCL updates."""

from __future__ import annotations

import numpy as np
import pytest

from bagtools.errors import BagtoolsError
from bagtools.transforms import se2_compose, se2_inverse
from bagtools_simulate.robot import ROUTE_NAMES, Limits, amcl_map_to_odom, drive, make_route, wheel_odometry
from bagtools_simulate.robot.amcl import UPDATE_MIN_A_RAD, UPDATE_MIN_D_M
from bagtools_simulate.robot.kinematics import integrate_increments, wrap_angle
from bagtools_simulate.robot.waffle import (
    JOINTS,
    MAX_ANGULAR_RADPS,
    MAX_LINEAR_MPS,
    ROBOT_RADIUS_M,
    WHEEL_RADIUS_M,
    WHEEL_SEPARATION_M,
    T_base_footprint_frame,
    urdf_text,
)
from bagtools_simulate.world import load_world

DT = 1.0 / 30.0


@pytest.fixture(scope="module")
def world():
    return load_world("turtlebot3_world")


def _drive(world, route: str, seconds: float, seed: int = 0, limits: Limits = Limits()):
    r = make_route(route, world, seed)
    return drive(r.path(seconds * limits.max_linear_mps + 1.0), world.spawn_xy_yaw, int(seconds * 30), DT, limits)


@pytest.mark.parametrize(("route", "seed"), [("lap", 0), ("figure8", 0), ("random", 0), ("random", 1), ("random", 7)])
def test_executed_route_keeps_robot_radius_from_obstacles(world, route, seed):
    motion = _drive(world, route, 150.0, seed)
    # every step boundary and the middle of every step
    mid = motion.pose_at_offset((np.arange(len(motion.v_mps)) + 0.5) * DT)
    clearance = world.clearance_m(np.vstack([motion.poses[:, :2], mid[:, :2]]))
    assert clearance.min() >= ROBOT_RADIUS_M
    assert np.sum(np.abs(motion.v_mps)) * DT > 15.0  # it really drives


def test_random_route_depends_on_seed(world):
    a, b = make_route("random", world, 1), make_route("random", world, 2)
    assert not np.array_equal(a.loop_xy, b.loop_xy)
    np.testing.assert_array_equal(a.loop_xy, make_route("random", world, 1).loop_xy)


def test_unknown_route_is_an_error(world):
    with pytest.raises(BagtoolsError, match="unknown route"):
        make_route("spiral", world)
    assert set(ROUTE_NAMES) == {"lap", "figure8", "random"}


def test_controller_respects_speed_and_acceleration_limits(world):
    limits = Limits(0.15, 1.0)
    motion = _drive(world, "figure8", 60.0, limits=limits)
    assert np.abs(motion.v_mps).max() <= 0.15 + 1e-12
    assert np.abs(motion.w_radps).max() <= 1.0 + 1e-12
    assert np.abs(np.diff(motion.v_mps)).max() <= limits.accel_linear_mps2 * DT + 1e-12
    assert np.abs(np.diff(motion.w_radps)).max() <= limits.accel_angular_radps2 * DT + 1e-12
    assert np.abs(motion.v_mps).max() > 0.14  # reaches the lowered limit


@pytest.mark.parametrize(("lin", "ang"), [(0.3, 1.0), (0.0, 1.0), (0.2, 2.0), (0.2, -1.0)])
def test_limits_above_the_waffle_or_not_positive_are_rejected(lin, ang):
    with pytest.raises(BagtoolsError):
        Limits(lin, ang).check()
    Limits(MAX_LINEAR_MPS, MAX_ANGULAR_RADPS).check()


def test_arc_integration_is_exact_on_a_circle():
    v, w, n = 0.2, 0.5, 300
    poses = integrate_increments((1.0, 2.0, 0.3), np.full(n, v * DT), np.full(n, w * DT))
    t = np.arange(n + 1) * DT
    radius = v / w
    cx, cy = 1.0 - radius * np.sin(0.3), 2.0 + radius * np.cos(0.3)
    expected_x = cx + radius * np.sin(0.3 + w * t)
    expected_y = cy - radius * np.cos(0.3 + w * t)
    np.testing.assert_allclose(poses[:, 0], expected_x, atol=1e-12)
    np.testing.assert_allclose(poses[:, 1], expected_y, atol=1e-12)


def test_pose_at_offset_matches_step_boundaries(world):
    motion = _drive(world, "lap", 10.0)
    k = np.arange(0, len(motion.poses), 7)
    np.testing.assert_allclose(motion.pose_at_offset(k * DT), motion.poses[k], atol=1e-9)


def _drift(world, level: str, seed: int = 3, seconds: float = 240.0):
    motion = _drive(world, "random", seconds, seed)
    odom = wheel_odometry(motion, level, np.random.default_rng(seed))
    in_map = se2_compose(np.asarray(world.spawn_xy_yaw), odom.poses)
    travelled = np.concatenate(([0.0], np.cumsum(np.abs(motion.v_mps) * DT)))
    return np.hypot(*(in_map[:, :2] - motion.poses[:, :2]).T), travelled, odom


def test_odometry_without_noise_has_zero_drift(world):
    err, _, odom = _drift(world, "none")
    assert err.max() < 1e-9
    assert (odom.radius_scale_left, odom.radius_scale_right, odom.separation_scale) == (1.0, 1.0, 1.0)


@pytest.mark.parametrize("seed", [0, 3])
def test_realistic_odometry_drift_grows_with_distance(world, seed):
    err, travelled, _ = _drift(world, "realistic", seed)
    early = err[travelled <= 0.1 * travelled[-1]].max()
    late = err[travelled >= 0.5 * travelled[-1]].mean()
    assert late > 2.0 * early > 0.0


def test_high_odometry_noise_drifts_more_on_average(world):
    # One bag's calibration errors can partly cancel, so compare the levels over several seeds.
    def mean_late_drift(level: str) -> float:
        drifts = []
        for seed in range(4):
            err, travelled, _ = _drift(world, level, seed, seconds=120.0)
            drifts.append(err[travelled >= 0.5 * travelled[-1]].mean())
        return float(np.mean(drifts))

    assert mean_late_drift("high") > 1.5 * mean_late_drift("realistic")


def test_odometry_twist_integrates_to_its_poses(world):
    _, _, odom = _drift(world, "realistic", seconds=30.0)
    again = integrate_increments((0.0, 0.0, 0.0), odom.v_mps * DT, odom.w_radps * DT)
    np.testing.assert_allclose(again, odom.poses, atol=1e-9)


def test_amcl_map_to_odom_jumps_only_at_update_points(world):
    motion = _drive(world, "figure8", 120.0)
    odom = wheel_odometry(motion, "realistic", np.random.default_rng(0))
    scans = np.arange(0, len(motion.poses), 6)
    out = amcl_map_to_odom(motion.poses[scans], odom.poses[scans], np.random.default_rng(1))
    change = np.any(np.diff(out.poses, axis=0) != 0.0, axis=1)
    # changes exactly at updates (after the first), constant otherwise
    np.testing.assert_array_equal(change, out.updated[1:])
    idx = np.flatnonzero(out.updated)
    assert idx[0] == 0 and 20 < len(idx) < len(scans) // 2
    o = odom.poses[scans]
    for a, b in zip(idx[:-1], idx[1:]):
        moved = np.hypot(*(o[a + 1 : b + 1, :2] - o[a, :2]).T)
        turned = np.abs(wrap_angle(o[a + 1 : b + 1, 2] - o[a, 2]))
        triggered = (moved >= UPDATE_MIN_D_M) | (turned >= UPDATE_MIN_A_RAD)
        assert triggered[-1] and not triggered[:-1].any()
    # at each update, map->odom composed with odometry is the truth within a few cm / degrees
    est = se2_compose(out.poses[idx], o[idx])
    err_xy = np.hypot(*(est[:, :2] - motion.poses[scans][idx, :2]).T)
    err_yaw = np.abs(wrap_angle(est[:, 2] - motion.poses[scans][idx, 2]))
    assert 0.005 < np.median(err_xy) < 0.08
    assert 0.002 < np.median(err_yaw) < np.deg2rad(3.0)


def test_se2_inverse_composes_to_identity():
    a = np.array([[1.0, -2.0, 0.7], [0.3, 0.1, -2.5]])
    np.testing.assert_allclose(se2_compose(a, se2_inverse(a)), 0.0, atol=1e-12)


@pytest.mark.parametrize(("frame", "xyz"), [("camera_rgb_optical_frame", (0.005, 0.018, 0.013)),
                                              ("camera_depth_optical_frame", (0.005, 0.028, 0.013))])
def test_static_chain_puts_the_optical_frames_z_forward_x_right_y_down(frame, xyz):
    T = T_base_footprint_frame(frame)
    # URDF rpy (-1.57, 0, -1.57): within 1e-3 of the exact optical rotation
    np.testing.assert_allclose(T[:3, 2], [1, 0, 0], atol=1e-3)
    np.testing.assert_allclose(T[:3, 0], [0, -1, 0], atol=1e-3)
    np.testing.assert_allclose(T[:3, 1], [0, 0, -1], atol=1e-3)
    np.testing.assert_allclose(T[:3, 3], [0.064 + xyz[0], -0.065 + xyz[1], 0.010 + 0.094 + xyz[2]], atol=1e-12)
    # base_scan at z 0.122 above base_link, as in the URDF robot_state_publisher publishes
    np.testing.assert_allclose(T_base_footprint_frame("base_scan")[:3, 3], [-0.064, 0.0, 0.132], atol=1e-12)


def test_joints_are_robotis_waffle_urdf():
    by_child = {j.child: j for j in JOINTS}
    expected = {
        "base_link": ("base_footprint", "fixed", (0, 0, 0.010)),
        "wheel_left_link": ("base_link", "continuous", (0, 0.144, 0.023)),
        "wheel_right_link": ("base_link", "continuous", (0, -0.144, 0.023)),
        "caster_back_right_link": ("base_link", "fixed", (-0.177, -0.064, -0.004)),
        "caster_back_left_link": ("base_link", "fixed", (-0.177, 0.064, -0.004)),
        "imu_link": ("base_link", "fixed", (0, 0, 0.068)),
        "base_scan": ("base_link", "fixed", (-0.064, 0, 0.122)),
        "camera_link": ("base_link", "fixed", (0.064, -0.065, 0.094)),
        "camera_rgb_frame": ("camera_link", "fixed", (0.005, 0.018, 0.013)),
        "camera_rgb_optical_frame": ("camera_rgb_frame", "fixed", (0, 0, 0)),
        "camera_depth_frame": ("camera_link", "fixed", (0.005, 0.028, 0.013)),
        "camera_depth_optical_frame": ("camera_depth_frame", "fixed", (0, 0, 0)),
    }
    assert set(by_child) == set(expected)
    for child, (parent, kind, xyz) in expected.items():
        j = by_child[child]
        assert (j.parent, j.kind) == (parent, kind), child
        np.testing.assert_allclose(j.xyz_m, xyz, atol=1e-12)
    # the wheel axis (joint z, after rpy -1.57 about x) points to the robot's left: +angle rolls forward
    T = by_child["wheel_left_link"].matrix()
    np.testing.assert_allclose(T[:3, 2], [0, 1, 0], atol=1e-3)


def test_urdf_text_parses_and_matches_the_joints():
    import xml.etree.ElementTree as ET

    root = ET.fromstring(urdf_text())
    assert root.tag == "robot" and root.get("name") == "turtlebot3_waffle"
    joints = {j.get("name"): j for j in root.findall("joint")}
    assert set(joints) == {j.name for j in JOINTS}
    links = {link.get("name") for link in root.findall("link")}
    assert links == {"base_footprint"} | {j.child for j in JOINTS}
    for j in JOINTS:
        el = joints[j.name]
        assert el.get("type") == j.kind
        assert el.find("parent").get("link") == j.parent and el.find("child").get("link") == j.child
        origin = el.find("origin")
        np.testing.assert_allclose([float(v) for v in origin.get("xyz").split()], j.xyz_m)
        np.testing.assert_allclose([float(v) for v in origin.get("rpy").split()], j.rpy_rad)


def test_wheel_angles_integrate_the_encoder_motion_the_odometry_used(world):
    motion = _drive(world, "lap", 20.0)
    for level in ("none", "realistic", "high"):
        odom = wheel_odometry(motion, level, np.random.default_rng(3))
        assert odom.wheel_left_rad[0] == odom.wheel_right_rad[0] == 0.0
        d_left, d_right = np.diff(odom.wheel_left_rad), np.diff(odom.wheel_right_rad)
        # wheel angle x radius is the distance the odometry integrated, step by step
        np.testing.assert_allclose(0.5 * (d_left + d_right) * WHEEL_RADIUS_M, odom.v_mps * DT, atol=1e-12)
        np.testing.assert_allclose((d_right - d_left) * WHEEL_RADIUS_M / WHEEL_SEPARATION_M, odom.w_radps * DT,
                                   atol=1e-12)
    # and the wheels turn about as far as the robot drove
    exact = wheel_odometry(motion, "none", np.random.default_rng(3))
    travel_m = 0.5 * (exact.wheel_left_rad[-1] + exact.wheel_right_rad[-1]) * WHEEL_RADIUS_M
    assert travel_m == pytest.approx(np.sum(motion.v_mps) * DT, rel=1e-9) and travel_m > 3.0
