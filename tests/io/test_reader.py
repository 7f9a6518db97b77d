"""The reader facade: every format, the real bags, and each kind of bad input."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from bagtools.errors import BagError, TopicError
from bagtools.io import decode_laserscan, decode_odometry, decode_pointcloud2, open_bag, read_tf_arrays
from tests.conftest import TYPESTORE, make_cloud, write_bag


def test_rosbag2_directory_and_bare_mcap_agree(synthetic_bag: Path) -> None:
    with open_bag(synthetic_bag) as bag:
        assert bag.kind == "rosbag2"
        assert {n: t.count for n, t in bag.topics.items()} == {"/cloud": 10, "/scan": 50, "/tf": 100, "/tf_static": 1}
        times = [r.log_time_ns for r in bag.raw_messages()]
    assert times == sorted(times) and len(times) == 161
    mcap_file = next(synthetic_bag.glob("*.mcap"))
    with open_bag(mcap_file) as bare:
        assert bare.kind == "mcap"
        assert [r.log_time_ns for r in bare.raw_messages()] == times


def test_sqlite3_storage(tmp_path: Path, synthetic_bag: Path) -> None:
    with open_bag(synthetic_bag) as bag:
        msgs = [(r.topic, r.msgtype, r.log_time_ns, r.msg) for r in bag.messages(["/scan", "/tf"])]
    db_bag = write_bag(tmp_path / "db", msgs, storage="sqlite3")
    for path in (db_bag, next(db_bag.glob("*.db3"))):
        with open_bag(path) as bag:
            assert bag.topics["/scan"].count == 50
            scan = decode_laserscan(next(bag.messages(["/scan"])).msg)
            assert scan.ranges_m.shape == (360,)


def test_topic_filter_and_require_topic(synthetic_bag: Path) -> None:
    with open_bag(synthetic_bag) as bag:
        assert {r.topic for r in bag.messages(["/scan"])} == {"/scan"}
        assert bag.require_topic("/scan", ["sensor_msgs/msg/LaserScan"]).count == 50
        with pytest.raises(TopicError, match="no topic '/nope'.*topics: /cloud, /scan, /tf, /tf_static"):
            bag.require_topic("/nope")
        with pytest.raises(TopicError, match="has type sensor_msgs/msg/LaserScan"):
            bag.require_topic("/scan", ["sensor_msgs/msg/PointCloud2"])


def test_missing_path(tmp_path: Path) -> None:
    with pytest.raises(BagError, match="no such file or directory") as info:
        open_bag(tmp_path / "missing.mcap")
    assert str(tmp_path / "missing.mcap") in str(info.value)


@pytest.mark.parametrize("name,content,problem", [
    ("notes.mcap", b"hello, this is text\n" * 20, "not a ROS bag"),
    ("empty.bag", b"", "file is empty"),
    ("random.db3", bytes(range(256)) * 4, "not a ROS bag"),
])
def test_not_a_bag(tmp_path: Path, name: str, content: bytes, problem: str) -> None:
    path = tmp_path / name
    path.write_bytes(content)
    with pytest.raises(BagError, match=problem):
        open_bag(path)


def test_directory_that_is_not_a_bag(tmp_path: Path) -> None:
    with pytest.raises(BagError, match="not a rosbag2 bag"):
        open_bag(tmp_path)


def test_wrong_suffix_is_named(tmp_path: Path, synthetic_bag: Path) -> None:
    renamed = tmp_path / "recording.bag"
    shutil.copy(next(synthetic_bag.glob("*.mcap")), renamed)
    with pytest.raises(BagError, match="holds mcap data.*rename it to '.mcap'"):
        open_bag(renamed)


def test_empty_bag(tmp_path: Path) -> None:
    from rosbags.rosbag2 import StoragePlugin, Writer

    with Writer(tmp_path / "empty", version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        writer.add_connection("/chatter", "std_msgs/msg/String", typestore=TYPESTORE)
    with pytest.raises(BagError, match="bag is empty"):
        open_bag(tmp_path / "empty")


def _truncate(src: Path, dst: Path, fraction: float) -> Path:
    data = src.read_bytes()
    dst.write_bytes(data[: int(len(data) * fraction)])
    return dst


@pytest.fixture
def cloud_bag(tmp_path: Path) -> Path:
    """A rosbag2 MCAP of 100 random 1000-point clouds (~1.6 MB, several zstd blocks)."""
    rng = np.random.default_rng(7)
    t0 = 1_700_000_000_000_000_000
    msgs = [("/cloud", "sensor_msgs/msg/PointCloud2", t0 + i * 100_000_000,
             make_cloud(t0 + i * 100_000_000, rng.normal(size=(1000, 3)))) for i in range(100)]
    return write_bag(tmp_path / "clouds", msgs)


@pytest.mark.parametrize("fraction", [0.15, 0.6, 0.9])
def test_truncated_mcap_recovers_every_message_before_the_cut(tmp_path: Path, cloud_bag: Path, fraction: float) -> None:
    full = next(cloud_bag.glob("*.mcap"))
    with open_bag(full) as bag:
        all_records = [(r.topic, r.log_time_ns, bytes(r.raw)) for r in bag.raw_messages()]
    cut = _truncate(full, tmp_path / "cut.mcap", fraction)
    with open_bag(cut) as bag:
        assert any("truncated MCAP" in w and "recovered" in w for w in bag.warnings)
        recovered = [(r.topic, r.log_time_ns, bytes(r.raw)) for r in bag.raw_messages()]
        assert bag.message_count == len(recovered)
        clouds = [decode_pointcloud2(r.msg) for r in bag.messages(["/cloud"])]
    assert 0 < len(recovered) < len(all_records)
    # Recovery is whole zstd blocks (<= 128 KiB of messages) short of the cut at most.
    assert len(recovered) >= fraction * len(all_records) - 15
    # The recovered messages are the full bag's first messages, byte for byte.
    assert recovered == all_records[: len(recovered)]
    assert clouds[0].points.shape == (1000, 3)


def test_cut_inside_the_only_compressed_block_is_an_error(tmp_path: Path, synthetic_bag: Path) -> None:
    # This small bag's messages sit in one zstd block, which cannot be decoded in part.
    cut = _truncate(next(synthetic_bag.glob("*.mcap")), tmp_path / "cut.mcap", 0.15)
    with pytest.raises(BagError, match="truncated MCAP.*no message could be recovered"):
        open_bag(cut)


def test_truncated_real_mcap(real_dir: Path, tmp_path: Path) -> None:
    cut = _truncate(real_dir / "nav2_turtlebot.mcap", tmp_path / "nav2_cut.mcap", 0.6)
    with open_bag(cut) as bag:
        n = bag.message_count
        assert 1000 < n < 8197
        assert sum(1 for _ in bag.messages()) == n
        assert f"recovered {n} messages" in bag.warnings[0]


def test_mcap_cut_inside_header_is_an_error(tmp_path: Path, synthetic_bag: Path) -> None:
    cut = _truncate(next(synthetic_bag.glob("*.mcap")), tmp_path / "tiny.mcap", 0.001)
    with pytest.raises(BagError, match="no message could be recovered|cannot read MCAP"):
        open_bag(cut)


def test_metadata_qos_mismatch_falls_back_to_storage(tmp_path: Path, synthetic_bag: Path) -> None:
    bag_dir = tmp_path / "qos"
    shutil.copytree(synthetic_bag, bag_dir)
    meta = bag_dir / "metadata.yaml"
    qos = ("\n      - history: keep_last\n        depth: 1\n        reliability: reliable\n"
           "        durability: transient_local\n        deadline: {sec: 0, nsec: 0}\n        lifespan: {sec: 0, nsec: 0}\n"
           "        liveliness: automatic\n        liveliness_lease_duration: {sec: 0, nsec: 0}\n"
           "        avoid_ros_namespace_conventions: false")
    text = meta.read_text()
    assert "offered_qos_profiles: []" in text
    meta.write_text(text.replace("offered_qos_profiles: []", "offered_qos_profiles:" + qos))
    from rosbags.highlevel import AnyReader

    with AnyReader([bag_dir]) as plain:  # the rosbags behaviour this guards against
        assert sum(1 for _ in plain.messages()) == 0
    with open_bag(bag_dir) as bag:  # MCAP storage is read directly: metadata QoS cannot hide messages
        assert sum(1 for _ in bag.messages()) == 161


def test_real_bags_topics_and_counts(real_dir: Path) -> None:
    expected = {
        "nav2_turtlebot.mcap": {"/odom": 2639, "/tf": 5422, "/tf_static": 1, "/amcl_pose": 135},
        "tf_example": {"/tf": 517, "/tf_static": 1},
        "tf_example.bag": {"/tf": 517, "/tf_static": 1},
        "turtlebot3_real_lidar_odom.bag": {"/scan": 291, "/odom": 1190, "/tf": 1189},
    }
    for name, counts in expected.items():
        with open_bag(real_dir / name) as bag:
            assert {n: t.count for n, t in bag.topics.items()} == counts, name
            assert sum(1 for _ in bag.raw_messages()) == sum(counts.values())


def test_real_tf_values(real_dir: Path) -> None:
    for name in ("tf_example", "tf_example.bag"):
        with open_bag(real_dir / name) as bag:
            dynamic, static = read_tf_arrays(bag)
        assert len(dynamic) == 517 and len(static) == 1
        assert set(dynamic.parent) == {"odom"} and set(dynamic.child) == {"base_footprint"}
        assert (static.parent[0], static.child[0]) == ("base_footprint", "base_link")
        np.testing.assert_allclose(np.linalg.norm(dynamic.rotation_xyzw, axis=1), 1.0, atol=1e-6)
        assert np.all(np.diff(dynamic.stamp_ns) > 0)
    with open_bag(real_dir / "nav2_turtlebot.mcap") as bag:
        dynamic, static = read_tf_arrays(bag)
    assert len(static) == 29
    assert {("map", "odom"), ("odom", "base_link")} <= set(zip(dynamic.parent, dynamic.child))


def test_real_turtlebot3_scan_and_odom(real_dir: Path) -> None:
    with open_bag(real_dir / "turtlebot3_real_lidar_odom.bag") as bag:
        scan = decode_laserscan(next(bag.messages(["/scan"])).msg)
        odom = decode_odometry(next(bag.messages(["/odom"])).msg)
    assert scan.frame_id == "base_scan" and scan.ranges_m.shape == (64,)
    # This bag's header says angle_max 3.4078 but holds 64 beams 0.0982 apart; beam
    # angles follow the ROS convention angle_min + i * angle_increment.
    np.testing.assert_allclose(scan.angles_rad[0], -1.3046, atol=1e-4)
    np.testing.assert_allclose(np.diff(scan.angles_rad), 0.0982, atol=1e-4)
    valid = scan.ranges_m[scan.valid]
    assert valid.size > 0 and valid.min() >= 0.092 and valid.max() <= 3.0
    assert (odom.frame_id, odom.child_frame_id) == ("odom", "base_link")
    np.testing.assert_allclose(np.linalg.norm(odom.orientation_xyzw), 1.0, atol=1e-6)


def test_undecodable_cdr_is_a_skipped_message_and_a_warning_never_a_traceback(tmp_path: Path, capsys) -> None:
    """CDR whose string length points past the message (rosbags' SerdeError): info, export and the readers skip it
    and say so; the commands end with exit 0 and a warning, not an internal error."""
    from rosbags.rosbag2 import StoragePlugin, Writer

    from bagtools.cli import main
    from tests.conftest import make_scan

    path = tmp_path / "bad_cdr"
    writer = Writer(path, version=9, storage_plugin=StoragePlugin.MCAP)
    with writer:
        conn = writer.add_connection("/scan", "sensor_msgs/msg/LaserScan", typestore=TYPESTORE)
        for i in range(5):
            t = 1_700_000_000_000_000_000 + i * 100_000_000
            data = TYPESTORE.serialize_cdr(make_scan(t, np.full(360, 2.0, dtype=np.float32)), "sensor_msgs/msg/LaserScan")
            writer.write(conn, t, b"\x00\x01\x00\x00" + b"\xff" * 40 if i == 2 else data)
    with open_bag(path) as bag:
        assert len(list(bag.messages(["/scan"]))) == 4
        assert any("cannot be decoded" in w and "1 on /scan" in w for w in bag.warnings)
    for argv in (["info", str(path)], ["export", str(path), "/scan", "--out", str(tmp_path / "scans.csv")]):
        with pytest.raises(SystemExit) as exit_info:
            main(argv)
        err = capsys.readouterr().err
        assert exit_info.value.code == 0 and "internal error" not in err and "Traceback" not in err, err


def test_a_topic_with_no_messages_is_listed_and_export_says_it_is_empty(tmp_path: Path, capsys) -> None:
    from rosbags.rosbag2 import StoragePlugin, Writer

    from bagtools.cli import main
    from tests.conftest import make_scan

    path = tmp_path / "empty_topic"
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        scan = writer.add_connection("/scan", "sensor_msgs/msg/LaserScan", typestore=TYPESTORE)
        writer.add_connection("/odom", "nav_msgs/msg/Odometry", typestore=TYPESTORE)
        writer.write(scan, 10**18, TYPESTORE.serialize_cdr(make_scan(10**18, np.ones(10, np.float32)),
                                                          "sensor_msgs/msg/LaserScan"))
    with open_bag(path) as bag:
        assert bag.topics["/odom"].count == 0 and bag.topics["/scan"].count == 1
    with pytest.raises(SystemExit):
        main(["info", str(path)])
    assert "/odom  nav_msgs/msg/Odometry            0" in capsys.readouterr().out
    with pytest.raises(SystemExit) as exit_info:
        main(["export", str(path), "/odom", "--out", str(tmp_path / "odom.csv")])
    err = capsys.readouterr().err
    assert exit_info.value.code == 2 and "topic '/odom' (nav_msgs/msg/Odometry) has no messages" in err, err
