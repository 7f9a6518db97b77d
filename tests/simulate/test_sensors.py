"""Tests for bagtools_simulate.sensors: the LDS-01 lidar and the depth camera."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from bagtools_simulate.sensors import DepthCamera, Lidar
from bagtools_simulate.world import World, load_world

SCAN_Z = 0.131
CAMERA_Z = 0.117  # camera_rgb_frame above the floor on the Waffle


@pytest.fixture(scope="module")
def tb3() -> World:
    return load_world("turtlebot3_world")


def T_map_optical(x: float, y: float, z: float, yaw: float, pitch: float = 0.0) -> np.ndarray:
    """Pose of an optical frame (z forward, x right, y down) for a camera body at x, y, z, yaw, pitch."""
    R_map_cam = Rotation.from_euler("xyz", [0.0, pitch, yaw]).as_matrix()
    R_cam_opt = Rotation.from_euler("xyz", [-math.pi / 2, 0.0, -math.pi / 2]).as_matrix()
    T = np.eye(4)
    T[:3, :3] = R_map_cam @ R_cam_opt
    T[:3, 3] = [x, y, z]
    return T


def to_map(points: np.ndarray, T: np.ndarray) -> np.ndarray:
    p = points.reshape(-1, 3).astype(np.float64)
    p = p[np.isfinite(p).all(axis=1)]
    return p @ T[:3, :3].T + T[:3, 3]


# ---------------------------------------------------------------------- lidar


def test_lidar_defaults_match_the_gazebo_lds01() -> None:
    lidar = Lidar()
    assert lidar.samples == 360
    assert lidar.angle_min_rad == 0.0
    assert lidar.angle_increment_rad == pytest.approx(6.28 / 359)
    assert lidar.angles_rad.shape == (360,)
    assert lidar.angles_rad[-1] == pytest.approx(6.28)
    assert (lidar.range_min_m, lidar.range_max_m, lidar.noise_sd_m, lidar.rate_hz) == (
        0.12,
        3.5,
        0.01,
        5.0,
    )


def test_scan_without_noise_equals_exact_distances(tb3: World) -> None:
    lidar = Lidar()
    # Beam 0 looks along the scanner's yaw: the pillar at (1.1, 0) is 0.45 m ahead, (0, 0) 0.35 behind.
    assert lidar.scan(tb3, (0.5, 0.0, SCAN_Z, 0.0), None)[0] == pytest.approx(0.45)
    assert lidar.scan(tb3, (0.5, 0.0, SCAN_Z, math.pi), None)[0] == pytest.approx(0.35)
    pose = (-2.0, -0.5, SCAN_Z, 0.3)
    ranges = lidar.scan(tb3, pose, None)
    exact = tb3.raycast_2d(np.array(pose[:2]), pose[3] + lidar.angles_rad, SCAN_Z, 3.5)
    valid = np.isfinite(exact)
    assert valid.sum() > 100
    np.testing.assert_allclose(ranges[valid], exact[valid], rtol=1e-6)


def test_scan_noise_is_gaussian_with_sd_001(tb3: World) -> None:
    lidar = Lidar()
    pose = (0.55, -0.55, SCAN_Z, 1.0)
    exact = lidar.true_ranges(tb3, pose)
    valid = (exact > 0.2) & (exact < 3.3)
    residuals = []
    rng = np.random.default_rng(11)
    for _ in range(20):
        ranges = lidar.scan(tb3, pose, rng)
        assert ranges.shape == (360,) and ranges.dtype == np.float32
        residuals.append(ranges[valid] - exact[valid])
    r = np.concatenate(residuals)
    assert np.abs(r).max() < 5 * 0.01
    assert np.mean(np.abs(r) < 3 * 0.01) > 0.99
    assert np.std(r) == pytest.approx(0.01, rel=0.1)
    assert abs(np.mean(r)) < 0.002


def test_scan_reports_inf_beyond_range_and_minus_inf_too_close(tb3: World) -> None:
    lidar = Lidar()
    # 0.1 m in front of the pillar at (1.1, 0): closer than range_min 0.12.
    ranges = lidar.scan(tb3, (1.1 - 0.15 - 0.1, 0.0, SCAN_Z, 0.0), np.random.default_rng(0))
    assert np.isneginf(ranges[0])
    # From the spawn point along +x nothing is within 3.5 m (the head is 4.6 m away).
    ranges = lidar.scan(tb3, (-2.0, -0.5, SCAN_Z, 0.0), np.random.default_rng(0))
    assert np.isposinf(ranges[0])
    finite = ranges[np.isfinite(ranges)]
    assert finite.min() >= 0.12 and finite.max() <= 3.5


def test_scan_is_deterministic_and_draws_one_normal_per_beam(tb3: World) -> None:
    lidar = Lidar()
    pose = (-2.0, -0.5, SCAN_Z, 0.0)
    a = lidar.scan(tb3, pose, np.random.default_rng(5))
    b = lidar.scan(tb3, pose, np.random.default_rng(5))
    c = lidar.scan(tb3, pose, np.random.default_rng(6))
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)
    rng = np.random.default_rng(9)
    lidar.scan(tb3, pose, rng)
    reference = np.random.default_rng(9)
    reference.normal(size=360)
    assert rng.random() == reference.random()


def test_lidar_rejects_bad_parameters() -> None:
    with pytest.raises(ValueError):
        Lidar(samples=0)
    with pytest.raises(ValueError):
        Lidar(range_min_m=4.0)


# ---------------------------------------------------------------------- depth camera


def test_camera_defaults_and_intrinsics() -> None:
    cam = DepthCamera()
    assert (cam.width, cam.height, cam.hfov_rad) == (160, 120, 1.02974)
    assert (cam.near_m, cam.far_m) == (0.4, 5.0)
    assert cam.focal_px == pytest.approx(80.0 / math.tan(1.02974 / 2))
    assert (cam.cx, cam.cy) == (79.5, 59.5)


def test_points_shape_dtype_and_centre_pixel(tb3: World) -> None:
    cam = DepthCamera(width=161, height=121, near_m=0.1)
    # Facing +x from 0.55 m before the pillar at (1.1, 0): the centre pixel sees it 0.4 m ahead.
    pts = cam.points(tb3, T_map_optical(0.55, 0.0, 0.25, 0.0), None)
    assert pts.shape == (121, 161, 3) and pts.dtype == np.float32
    np.testing.assert_allclose(pts[60, 80], [0.0, 0.0, 0.4], atol=1e-6)
    # Pixel geometry: x / z = (u - cx) / f and y / z = (v - cy) / f.
    valid = np.isfinite(pts[..., 2])
    v, u = np.nonzero(valid)
    np.testing.assert_allclose(pts[v, u, 0] / pts[v, u, 2], (u - cam.cx) / cam.focal_px, atol=1e-5)
    np.testing.assert_allclose(pts[v, u, 1] / pts[v, u, 2], (v - cam.cy) / cam.focal_px, atol=1e-5)


@pytest.mark.parametrize(
    "pose",
    [
        (-2.0, -0.5, CAMERA_Z, 0.0, 0.0),
        (0.55, 0.55, CAMERA_Z, 2.0, 0.0),
        (2.0, 0.0, CAMERA_Z, -2.5, 0.0),
        (-0.6, 0.0, 0.8, 0.0, 0.7),  # above the pillars, pitched down: sees a cap
        (0.5, -1.6, 0.3, -1.2, -0.3),  # pitched up: sky beyond the walls
    ],
)
def test_noise_free_points_land_on_world_surfaces(tb3: World, pose) -> None:
    T = T_map_optical(*pose)
    pts = DepthCamera().points(tb3, T, None)
    valid = np.isfinite(pts[..., 2])
    assert valid.mean() > 0.3
    assert np.array_equal(np.isnan(pts).any(axis=2), ~valid)
    in_map = to_map(pts, T)
    assert tb3.surface_distance_m(in_map).max() < 1e-6
    if pose[2] > 0.5:
        assert np.sum(np.abs(in_map[:, 2] - 0.5) < 1e-6) > 100  # on the pillar's top cap
    z = pts[..., 2][valid]
    assert z.min() > 0.4 and z.max() < 5.0


def test_rays_to_the_sky_and_beyond_far_are_nan(tb3: World) -> None:
    # Pitched 60 degrees up: the upper rows see over every wall.
    pts = DepthCamera().points(tb3, T_map_optical(0.0, 0.6, CAMERA_Z, 0.0, -math.pi / 3), None)
    assert np.isnan(pts[0]).all()
    # With far = 1 m, nothing farther than 1 m survives.
    cam = DepthCamera(far_m=1.0)
    T = T_map_optical(-2.0, -0.5, CAMERA_Z, 0.0)
    pts = cam.points(tb3, T, None)
    valid = np.isfinite(pts[..., 2])
    assert valid.any() and (~valid).any()
    assert pts[..., 2][valid].max() < 1.0
    full = DepthCamera().depth(tb3, T, None)
    np.testing.assert_array_equal(valid, full < 1.0)


def test_depth_noise_grows_with_depth_and_is_deterministic(tb3: World) -> None:
    cam = DepthCamera()
    T = T_map_optical(-2.0, -0.5, CAMERA_Z, 0.0)
    exact = cam.depth(tb3, T, None)
    a = cam.points(tb3, T, np.random.default_rng(4))
    b = cam.points(tb3, T, np.random.default_rng(4))
    np.testing.assert_array_equal(a, b)
    noisy = cam.depth(tb3, T, np.random.default_rng(8))
    both = np.isfinite(exact) & np.isfinite(noisy)
    scaled = (noisy[both] - exact[both]) / exact[both] ** 2
    assert np.std(scaled) == pytest.approx(cam.noise_sd_at_1m_m, rel=0.1)
    # Noisy points stay on their pixel rays.
    v, u = np.nonzero(np.isfinite(a[..., 2]))
    np.testing.assert_allclose(a[v, u, 0] / a[v, u, 2], (u - cam.cx) / cam.focal_px, atol=1e-5)


def test_full_size_640x480_cloud(tb3: World) -> None:
    cam = DepthCamera(width=640, height=480)
    T = T_map_optical(0.55, 0.55, CAMERA_Z, 2.0)
    pts = cam.points(tb3, T, np.random.default_rng(0))
    assert pts.shape == (480, 640, 3) and pts.dtype == np.float32
    small = DepthCamera().points(tb3, T, None)
    assert np.isfinite(pts[..., 2]).mean() == pytest.approx(np.isfinite(small[..., 2]).mean(), abs=0.02)


def test_camera_rejects_bad_parameters(tb3: World) -> None:
    with pytest.raises(ValueError):
        DepthCamera(width=0)
    with pytest.raises(ValueError):
        DepthCamera(hfov_rad=4.0)
    with pytest.raises(ValueError):
        DepthCamera(near_m=6.0)
    with pytest.raises(ValueError):
        DepthCamera().points(tb3, np.eye(3), None)


def test_imu_noise_statistics_are_turtlebot3_gazebo_s():
    from bagtools_simulate.robot.controller import Motion
    from bagtools_simulate.sensors import Imu

    # a standing robot for 100 s: readings are gravity and noise only
    n = 3000
    still = Motion(1 / 30, np.zeros(n), np.zeros(n), np.zeros((n + 1, 3)))
    imu = Imu()
    t = np.arange(int(100 * imu.rate_hz)) / imu.rate_hz
    s = imu.samples(still, t, np.random.default_rng(0))
    gyro, acc = s.angular_velocity_radps, s.linear_acceleration_mps2
    np.testing.assert_allclose(gyro.std(axis=0), 2e-4, rtol=0.03)
    np.testing.assert_allclose(acc.std(axis=0), 1.7e-2, rtol=0.03)
    np.testing.assert_allclose(gyro.mean(axis=0), 0.0, atol=1e-5)
    np.testing.assert_allclose(acc.mean(axis=0), [0.0, 0.0, 9.8], atol=1e-3)
    np.testing.assert_allclose(s.quat_xyzw, np.tile([0, 0, 0, 1.0], (len(t), 1)))
    assert np.allclose(imu.angular_velocity_covariance.reshape(3, 3), np.eye(3) * 4e-8)
    assert np.allclose(imu.linear_acceleration_covariance.reshape(3, 3), np.eye(3) * 2.89e-4)


def test_imu_measures_the_turn_rate_centripetal_and_forward_acceleration():
    from bagtools_simulate.robot.controller import Motion
    from bagtools_simulate.robot.kinematics import integrate_increments
    from bagtools_simulate.sensors import Imu

    dt, n = 1 / 30, 300
    v = np.minimum(np.arange(n) * 0.01, 0.2)  # accelerate at 0.3 m/s^2, then cruise
    w = np.full(n, 0.5)
    motion = Motion(dt, v, w, integrate_increments((1.0, 2.0, 0.3), v * dt, w * dt))
    t = np.arange(int(n * dt * 200)) / 200.0
    s = Imu().samples(motion, t, None)
    k = np.minimum((t / dt).astype(int), n - 1)
    np.testing.assert_allclose(s.angular_velocity_radps[:, 2], 0.5)
    np.testing.assert_allclose(s.linear_acceleration_mps2[:, 1], v[k] * 0.5)  # v w, to the left
    accelerating = k[(k > 0) & (k < 19)]
    np.testing.assert_allclose(s.linear_acceleration_mps2[(k > 0) & (k < 19), 0], 0.01 / dt)
    assert len(accelerating) > 0 and np.all(s.linear_acceleration_mps2[k > 25, 0] == 0.0)
    yaw = 2.0 * np.arctan2(s.quat_xyzw[:, 2], s.quat_xyzw[:, 3])
    np.testing.assert_allclose(np.unwrap(yaw), motion.pose_at_offset(t)[:, 2], atol=1e-9)


def test_depth_camera_intrinsics_matrices():
    cam = DepthCamera(width=160, height=120)
    np.testing.assert_allclose(cam.K, [[cam.focal_px, 0, 79.5], [0, cam.focal_px, 59.5], [0, 0, 1]])
    np.testing.assert_allclose(cam.P[:, :3], cam.K)
    assert not cam.P[:, 3].any()
    assert cam.focal_px == pytest.approx(160 / (2 * np.tan(1.02974 / 2)))
