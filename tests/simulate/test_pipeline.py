"""The simulated bag end to end: read back, sensors against the truth, tf, stamps, determinism, atomicity."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from rosbags.highlevel import AnyReader
from rosbags.interfaces import QosDurability
from scipy.spatial.transform import Rotation

import bagtools_simulate.pipeline as pipeline
from bagtools.errors import BagtoolsError, OutputExistsError
from bagtools_simulate.pipeline import SimConfig, parse_cloud_size, simulate_bag
from bagtools_simulate.robot.waffle import JOINTS, STATIC_TRANSFORMS, WHEEL_RADIUS_M, WHEEL_SEPARATION_M, T_base_footprint_frame
from bagtools_simulate.sensors import DepthCamera
from bagtools_simulate.world import load_world

SHORT = SimConfig(duration_s=21.0, cloud_size=(40, 30), cloud_rate_hz=2.0)


def read_bag(path: Path) -> dict[str, list[tuple[int, object, bytes]]]:
    """topic -> [(log_ns, message, raw bytes)] in bag order."""
    out: dict[str, list] = {}
    with AnyReader([path]) as reader:
        for conn, log_ns, raw in reader.messages():
            out.setdefault(conn.topic, []).append((log_ns, reader.deserialize(raw, conn.msgtype), bytes(raw)))
    return out


def header_ns(header) -> int:
    return header.stamp.sec * 1_000_000_000 + header.stamp.nanosec


def stamp_ns(msg) -> int:
    return header_ns(msg.header)


def yaw_of(q) -> float:
    return float(Rotation.from_quat([q.x, q.y, q.z, q.w]).as_euler("xyz")[2])


@pytest.fixture(scope="module")
def world():
    return load_world("turtlebot3_world")


@pytest.fixture(scope="module")
def bag(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("sim") / "bag"
    simulate_bag(out, SHORT)
    return out


@pytest.fixture(scope="module")
def msgs(bag):
    return read_bag(bag)


def truth_by_stamp(msgs) -> dict[int, np.ndarray]:
    return {
        stamp_ns(m): np.array([m.pose.pose.position.x, m.pose.pose.position.y, yaw_of(m.pose.pose.orientation)])
        for _, m, _ in msgs["/ground_truth"]
    }


def test_all_topics_read_back_with_expected_counts(msgs):
    counts = {t: len(v) for t, v in msgs.items()}
    assert counts == {
        "/simulation/world": 1, "/tf_static": 1, "/odom": 631, "/ground_truth": 631, "/scan": 106,
        "/tf": 631 + 106 + 631, "/camera/depth/points": 43, "/clicked_point": 1, "/robot_description": 1,
        "/joint_states": 631, "/imu": 21 * 200 + 1, "/camera/depth/camera_info": 43,
    }


def test_world_topic_carries_geometry_and_config(msgs, world):
    data = json.loads(msgs["/simulation/world"][0][1].data)
    assert data["world"] == world.to_json()
    assert data["config"]["duration_s"] == 21.0 and data["config"]["route"] == "lap"


def test_tf_static_has_the_waffle_fixed_joints_latched(bag, msgs):
    [(log_ns, msg, _)] = msgs["/tf_static"]
    got = {(t.header.frame_id, t.child_frame_id): t.transform for t in msg.transforms}
    assert len(got) == len(STATIC_TRANSFORMS) == 10
    for st in STATIC_TRANSFORMS:
        tr = got[(st.parent, st.child)]
        np.testing.assert_allclose([tr.translation.x, tr.translation.y, tr.translation.z], st.xyz_m)
        np.testing.assert_allclose([tr.rotation.x, tr.rotation.y, tr.rotation.z, tr.rotation.w], st.quat_xyzw)
    assert log_ns == min(m[0] for v in msgs.values() for m in v)
    with AnyReader([bag]) as reader:
        [conn] = [c for c in reader.connections if c.topic == "/tf_static"]
        [qos] = conn.ext.offered_qos_profiles
    # as the recorder stores a publisher's offer: durability from discovery, history unknown, depth 0
    assert qos.durability == QosDurability.TRANSIENT_LOCAL and qos.depth == 0


def test_bag_time_is_stamp_plus_latency_and_order_differs(msgs):
    ranges = {"/odom": (1, 5), "/ground_truth": (1, 5), "/scan": (10, 30), "/camera/depth/points": (20, 60),
              "/clicked_point": (1, 5), "/joint_states": (1, 5), "/imu": (1, 3), "/camera/depth/camera_info": (20, 60)}
    for topic, (lo, hi) in ranges.items():
        lat_ms = np.array([(log - stamp_ns(m)) / 1e6 for log, m, _ in msgs[topic]])
        assert lat_ms.min() >= lo - 1e-6 and lat_ms.max() <= hi + 1e-6, topic
    everything = sorted(
        (log, stamp_ns(m)) for topic, v in msgs.items() if topic not in ("/tf", "/tf_static", "/simulation/world", "/robot_description")
        for log, m, _ in v
    )
    stamps = np.array([s for _, s in everything])
    assert np.any(np.diff(stamps) < 0)  # bag order is not stamp order


def test_map_to_odom_is_amcl_like(msgs):
    scans = [stamp_ns(m) for _, m, _ in msgs["/scan"]]
    map_odom = [(t.header, t.transform, log) for log, m, _ in msgs["/tf"] for t in m.transforms if t.header.frame_id == "map"]
    assert len(map_odom) == len(scans)
    for (header, _, log), scan_stamp in zip(map_odom, scans):
        assert header_ns(header) == scan_stamp + 1_000_000_000  # transform tolerance
        assert log < scan_stamp + 1_000_000_000
    values = np.array([[tr.translation.x, tr.translation.y, yaw_of(tr.rotation)] for _, tr, _ in map_odom])
    changes = np.flatnonzero(np.any(np.diff(values, axis=0) != 0, axis=1))
    assert 0 < len(changes) < len(values) // 2  # held between updates, jumps at updates


def test_scans_agree_with_exact_ray_distances(msgs, world):
    truth = truth_by_stamp(msgs)
    T_scan = T_base_footprint_frame("base_scan")
    residuals, mismatched_inf = [], 0
    for _, scan, _ in msgs["/scan"]:
        x, y, yaw = truth[stamp_ns(scan)]
        origin = np.array([x + np.cos(yaw) * T_scan[0, 3], y + np.sin(yaw) * T_scan[0, 3]])
        angles = yaw + scan.angle_min + scan.angle_increment * np.arange(len(scan.ranges))
        exact = world.raycast_2d(origin, angles, T_scan[2, 3], scan.range_max)
        ranges = scan.ranges.astype(np.float64)
        both = np.isfinite(ranges) & np.isfinite(exact)
        residuals.append(ranges[both] - exact[both])
        mismatched_inf += int(np.sum(np.isfinite(ranges) != np.isfinite(exact)))
    res = np.concatenate(residuals)
    assert len(res) > 10_000
    assert abs(res.mean()) < 0.002 and 0.007 < res.std() < 0.013
    assert mismatched_inf < 0.01 * len(res)  # only beams grazing the 3.5 m limit
    assert msgs["/scan"][0][1].header.frame_id == "base_scan"


def test_clouds_land_on_true_surfaces(msgs, world):
    T_base_opt = T_base_footprint_frame("camera_rgb_optical_frame")  # the lab's frame, the Waffle plugin's
    poses = sorted(truth_by_stamp(msgs).items())
    t_truth = np.array([t for t, _ in poses])
    xyyaw = np.array([p for _, p in poses])
    dists = []
    for _, cloud, _ in msgs["/camera/depth/points"]:
        assert cloud.header.frame_id == "camera_rgb_optical_frame" and not cloud.is_dense
        assert (cloud.point_step, cloud.row_step, cloud.height, cloud.width) == (12, 12 * 40, 30, 40)
        pts = np.frombuffer(cloud.data, dtype="<f4").reshape(-1, 3).astype(np.float64)
        pts = pts[np.isfinite(pts).all(axis=1)]
        i = int(np.searchsorted(t_truth, stamp_ns(cloud)))  # clouds at 2 Hz fall on 30 Hz steps
        assert t_truth[i] == stamp_ns(cloud)
        x, y, yaw = xyyaw[i]
        T = np.eye(4)
        T[:2, :2] = [[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]]
        T[:2, 3] = (x, y)
        T = T @ T_base_opt
        dists.append(world.surface_distance_m(pts @ T[:3, :3].T + T[:3, 3]))
    d = np.concatenate(dists)
    assert len(d) > 10_000
    assert np.median(d) < 0.01 and np.quantile(d, 0.99) < 0.05


def test_same_config_gives_identical_messages_and_seed_changes_them(tmp_path, msgs):
    again = read_bag(simulate_bag(tmp_path / "again", SHORT).path)
    assert {t: [(log, raw) for log, _, raw in v] for t, v in again.items()} == {
        t: [(log, raw) for log, _, raw in v] for t, v in msgs.items()
    }
    other = read_bag(simulate_bag(tmp_path / "other", SimConfig(duration_s=3.0, seed=1, cloud=False)).path)
    base = read_bag(simulate_bag(tmp_path / "base", SimConfig(duration_s=3.0, seed=0, cloud=False)).path)
    assert [r for _, _, r in other["/scan"]] != [r for _, _, r in base["/scan"]]
    assert "/camera/depth/points" not in base


def test_no_odometry_noise_means_odom_equals_truth(tmp_path):
    summary = simulate_bag(tmp_path / "exact", SimConfig(duration_s=10.0, odom_noise="none", cloud=False))
    assert summary.final_drift_m < 1e-9 and summary.distance_m > 1.0
    noisy = simulate_bag(tmp_path / "noisy", SimConfig(duration_s=10.0, odom_noise="high", cloud=False))
    assert noisy.final_drift_m > 1e-3


def test_refuses_existing_output_without_force(tmp_path):
    out = tmp_path / "bag"
    out.mkdir()
    (out / "keep.txt").write_text("mine")
    with pytest.raises(OutputExistsError):
        simulate_bag(out, SimConfig(duration_s=1.0, cloud=False))
    assert (out / "keep.txt").read_text() == "mine"
    with pytest.raises(OutputExistsError, match="did not write"):  # --force never deletes a user's directory
        simulate_bag(out, SimConfig(duration_s=1.0, cloud=False), force=True)
    assert (out / "keep.txt").read_text() == "mine"
    (out / "keep.txt").unlink()
    simulate_bag(out, SimConfig(duration_s=1.0, cloud=False), force=True)
    simulate_bag(out, SimConfig(duration_s=2.0, cloud=False), force=True)  # its own bag is replaced
    assert (out / "metadata.yaml").exists() and sorted(p.name for p in tmp_path.iterdir()) == ["bag"]


@pytest.mark.parametrize("exc", [RuntimeError("boom"), KeyboardInterrupt()])
def test_error_mid_write_leaves_nothing_behind(tmp_path, monkeypatch, exc):
    calls = {"n": 0}
    original = pipeline.MessageBuilder.laser_scan

    def failing(self, *args, **kwargs):
        calls["n"] += 1
        if calls["n"] == 5:
            raise exc
        return original(self, *args, **kwargs)

    monkeypatch.setattr(pipeline.MessageBuilder, "laser_scan", failing)
    with pytest.raises(type(exc)):
        simulate_bag(tmp_path / "bag", SimConfig(duration_s=5.0, cloud=False))
    assert calls["n"] == 5
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(("distro", "version"), [("humble", 5), ("jazzy", 9)])
def test_metadata_version_per_distro_and_read_back(tmp_path, distro, version):
    out = simulate_bag(tmp_path / distro, SimConfig(duration_s=2.0, cloud=False, ros_distro=distro)).path
    text = (out / "metadata.yaml").read_text()
    assert f"  version: {version}\n" in text
    assert "storage_identifier: mcap" in text
    with AnyReader([out]) as reader:
        assert reader.message_count == sum(1 for _ in reader.messages())
        assert {c.topic: c.msgcount for c in reader.connections}["/odom"] == 61
    mcap = out / f"{distro}.mcap"
    assert mcap.read_bytes()[:8] == b"\x89MCAP0\r\n" and b"zstd" in mcap.read_bytes()


@pytest.mark.parametrize(
    ("config", "message"),
    [
        (SimConfig(duration_s=-1.0), "--duration"),
        (SimConfig(max_linear_mps=0.3), "--max-linear"),
        (SimConfig(max_angular_radps=0.0), "--max-angular"),
        (SimConfig(cloud_rate_hz=0.0), "--cloud-rate"),
        (SimConfig(cloud_size=(1, 100)), "--cloud-size"),
        (SimConfig(route="spiral"), "unknown route"),
        (SimConfig(odom_noise="some"), "unknown odometry noise"),
        (SimConfig(ros_distro="iron"), "unknown ROS distro"),
    ],
)
def test_invalid_config_is_a_one_line_error(tmp_path, config, message):
    with pytest.raises(BagtoolsError, match=message):
        simulate_bag(tmp_path / "bag", config)
    assert not (tmp_path / "bag").exists()


def test_parse_cloud_size():
    assert parse_cloud_size("640x480") == (640, 480)
    for bad in ("640", "640x", "x480", "640*480", "-1x2"):
        with pytest.raises(BagtoolsError, match="WIDTHxHEIGHT"):
            parse_cloud_size(bad)


def test_tf_tree_is_the_one_a_real_turtlebot3_waffle_has(bag):
    from bagtools.tf import TfBuffer

    buffer = TfBuffer.from_bag(bag)
    parents = {
        "odom": "map", "base_footprint": "odom", "base_link": "base_footprint", "base_scan": "base_link",
        "imu_link": "base_link", "wheel_left_link": "base_link", "wheel_right_link": "base_link",
        "caster_back_left_link": "base_link", "caster_back_right_link": "base_link", "camera_link": "base_link",
        "camera_rgb_frame": "camera_link", "camera_rgb_optical_frame": "camera_rgb_frame",
        "camera_depth_frame": "camera_link", "camera_depth_optical_frame": "camera_depth_frame",
    }
    t_ns = 1_700_000_005_000_000_000
    for child, parent in parents.items():
        assert buffer.can_transform(parent, child, t_ns), (parent, child)
    T = buffer.lookup("base_link", "base_scan", t_ns)
    np.testing.assert_allclose(T[:3, 3], [-0.064, 0.0, 0.122], atol=1e-12)  # the URDF's, not the SDF's 0.121
    T = buffer.lookup("base_link", "imu_link", t_ns)
    np.testing.assert_allclose(T[:3, 3], [0.0, 0.0, 0.068], atol=1e-12)


def test_joint_states_follow_the_odometry_and_drive_the_wheel_frames(msgs):
    joints = [m for _, m, _ in msgs["/joint_states"]]
    odom = [m for _, m, _ in msgs["/odom"]]
    assert [stamp_ns(j) for j in joints] == [stamp_ns(o) for o in odom]
    assert all(list(j.name) == ["wheel_left_joint", "wheel_right_joint"] for j in joints)
    pos = np.array([j.position for j in joints])
    vel = np.array([j.velocity for j in joints])
    xy = np.array([[o.pose.pose.position.x, o.pose.pose.position.y] for o in odom])
    yaw = np.unwrap([yaw_of(o.pose.pose.orientation) for o in odom])
    # wheel angle x radius: the distance the odometry moved; the difference: its heading
    ds = 0.5 * np.diff(pos, axis=0).sum(axis=1) * WHEEL_RADIUS_M
    np.testing.assert_allclose(np.abs(ds), np.hypot(*np.diff(xy, axis=0).T), atol=2e-5)
    dyaw = np.diff(pos[:, 1] - pos[:, 0]) * WHEEL_RADIUS_M / WHEEL_SEPARATION_M
    np.testing.assert_allclose(dyaw, np.diff(yaw), atol=1e-9)
    assert pos[-1].mean() * WHEEL_RADIUS_M > 3.0
    np.testing.assert_allclose(vel[1:], np.diff(pos, axis=0) * 30.0, atol=1e-9)  # rad/s over the last step
    # robot_state_publisher's /tf for the wheels: same stamps, rotation about the joint axis by the angle
    wheel_tf = {}
    for _, m, _ in msgs["/tf"]:
        for t in m.transforms:
            if t.child_frame_id.startswith("wheel_"):
                wheel_tf.setdefault(t.child_frame_id, []).append(t)
    by_name = {j.child: j for j in JOINTS}
    for i, frame in enumerate(("wheel_left_link", "wheel_right_link")):
        tfs = wheel_tf[frame]
        assert [header_ns(t.header) for t in tfs] == [stamp_ns(j) for j in joints]
        assert all(t.header.frame_id == "base_link" for t in tfs)
        for k in (0, 100, 400):
            q = tfs[k].transform.rotation
            expected = by_name[frame].matrix(pos[k, i])[:3, :3]
            np.testing.assert_allclose(Rotation.from_quat([q.x, q.y, q.z, q.w]).as_matrix(), expected, atol=1e-12)


def test_imu_is_gazebo_like_in_imu_link(msgs):
    imu = [m for _, m, _ in msgs["/imu"]]
    assert all(m.header.frame_id == "imu_link" for m in imu)
    stamps = np.array([stamp_ns(m) for m in imu])
    assert np.all(np.diff(stamps) == 5_000_000)  # 200 Hz
    gyro = np.array([[m.angular_velocity.x, m.angular_velocity.y, m.angular_velocity.z] for m in imu])
    acc = np.array([[m.linear_acceleration.x, m.linear_acceleration.y, m.linear_acceleration.z] for m in imu])
    assert 1.6e-4 < gyro[:, 0].std() < 2.4e-4 and abs(gyro[:, :2].mean()) < 2e-5
    assert 9.79 < acc[:, 2].mean() < 9.81 and 0.015 < acc[:, 2].std() < 0.019
    np.testing.assert_allclose(imu[0].angular_velocity_covariance, np.diag([4e-8] * 3).ravel())
    np.testing.assert_allclose(imu[0].linear_acceleration_covariance, np.diag([1.7e-2**2] * 3).ravel())
    # orientation is the true heading; gyro z is the true turn rate within the noise
    truth = truth_by_stamp(msgs)
    on_steps = [(m, truth[stamp_ns(m)]) for m in imu if stamp_ns(m) in truth][1:]
    assert len(on_steps) > 100
    for m, (_, _, yaw) in on_steps[::20]:
        assert abs((yaw_of(m.orientation) - yaw + np.pi) % (2 * np.pi) - np.pi) < 1e-9
    w_true = np.array([t.twist.twist.angular.z for _, t, _ in msgs["/ground_truth"]])
    assert np.abs(gyro[:, 2]).max() <= np.abs(w_true).max() + 1e-3


def test_camera_info_matches_the_depth_camera(msgs):
    camera = DepthCamera(width=40, height=30)
    infos = [m for _, m, _ in msgs["/camera/depth/camera_info"]]
    clouds = [m for _, m, _ in msgs["/camera/depth/points"]]
    assert [stamp_ns(i) for i in infos] == [stamp_ns(c) for c in clouds]
    info = infos[0]
    assert info.header.frame_id == clouds[0].header.frame_id == "camera_rgb_optical_frame"
    assert (info.width, info.height, info.distortion_model) == (40, 30, "plumb_bob")
    np.testing.assert_allclose(info.k, camera.K.ravel())
    np.testing.assert_allclose(info.p, camera.P.ravel())
    assert not np.any(info.d)
    # the cloud's points project onto their own pixels through K
    pts = np.frombuffer(clouds[5].data, dtype="<f4").reshape(30, 40, 3).astype(np.float64)
    v, u = np.nonzero(np.isfinite(pts[:, :, 2]))
    K = np.asarray(info.k).reshape(3, 3)
    proj = pts[v, u] @ K.T
    np.testing.assert_allclose(proj[:, 0] / proj[:, 2], u, atol=1e-3)
    np.testing.assert_allclose(proj[:, 1] / proj[:, 2], v, atol=1e-3)


def test_robot_description_is_latched_and_matches_tf_static(bag, msgs):
    import xml.etree.ElementTree as ET

    [(log_ns, desc, _)] = msgs["/robot_description"]
    assert log_ns == msgs["/tf_static"][0][0]
    root = ET.fromstring(desc.data)
    joints = {j.find("child").get("link"): j for j in root.findall("joint")}
    [(_, static, _)] = msgs["/tf_static"]
    for t in static.transforms:
        j = joints[t.child_frame_id]
        assert j.get("type") == "fixed" and j.find("parent").get("link") == t.header.frame_id
        xyz = [float(x) for x in j.find("origin").get("xyz").split()]
        rpy = [float(x) for x in j.find("origin").get("rpy").split()]
        tr, q = t.transform.translation, t.transform.rotation
        np.testing.assert_allclose([tr.x, tr.y, tr.z], xyz, atol=1e-12)
        np.testing.assert_allclose(Rotation.from_quat([q.x, q.y, q.z, q.w]).as_matrix(),
                                   Rotation.from_euler("xyz", rpy).as_matrix(), atol=1e-12)
    assert {joints[c].get("type") for c in ("wheel_left_link", "wheel_right_link")} == {"continuous"}
    with AnyReader([bag]) as reader:
        [conn] = [c for c in reader.connections if c.topic == "/robot_description"]
        assert conn.ext.offered_qos_profiles[0].durability == QosDurability.TRANSIENT_LOCAL
