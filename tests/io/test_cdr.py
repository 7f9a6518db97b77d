"""Scans and clouds decoded straight from CDR bytes are exactly what the rosbags path decodes, or left to it."""

from __future__ import annotations

import dataclasses
import struct

import numpy as np
import pytest

from bagtools.io import decode_laserscan, decode_pointcloud2, open_bag
from bagtools.io.cdr import laserscan_from_cdr, pointcloud2_from_cdr, tf_from_cdr
from bagtools.io.decode import DecodeError, tf_rows
from tests.conftest import FIXTURES, TYPESTORE, make_cloud, make_scan, make_tf

SCAN = "sensor_msgs/msg/LaserScan"
CLOUD = "sensor_msgs/msg/PointCloud2"


def same(a: object, b: object) -> None:
    """Two decoded dataclasses hold the same values, arrays bit for bit (NaN where NaN) and of the same dtype."""
    assert type(a) is type(b)
    for f in dataclasses.fields(a):
        x, y = getattr(a, f.name), getattr(b, f.name)
        if isinstance(x, np.ndarray) or isinstance(y, np.ndarray):
            assert x is not None and y is not None and x.dtype == y.dtype and x.shape == y.shape, f.name
            assert np.array_equal(x, y, equal_nan=True), f.name
        else:
            assert x == y, f.name


def test_every_scan_and_cloud_of_the_fixtures_decodes_as_rosbags_decodes_it() -> None:
    checked = {SCAN: 0, CLOUD: 0}
    for bag_path in (FIXTURES / "sim_lap_cloud_20s", FIXTURES / "sim_random_nocloud_20s"):
        with open_bag(bag_path) as bag:
            topics = [t for t, info in bag.topics.items() if info.msgtype in checked]
            for raw in bag.raw_messages(topics):
                msg = bag.deserialize(raw).msg
                if raw.msgtype == SCAN:
                    same(laserscan_from_cdr(raw.raw), decode_laserscan(msg))
                else:
                    for attributes in (False, True):
                        same(pointcloud2_from_cdr(raw.raw, attributes=attributes),
                             decode_pointcloud2(msg, attributes=attributes))
                checked[raw.msgtype] += 1
    assert checked[SCAN] > 50 and checked[CLOUD] > 10


@pytest.mark.parametrize("kind", ["padded rows", "float64 big-endian", "odd frame id"])
def test_clouds_of_other_layouts_decode_the_same(kind: str) -> None:
    rng = np.random.default_rng(3)
    xyz = rng.uniform(-5, 5, (24, 3))
    xyz[::5] = np.nan
    msg = {"padded rows": lambda: make_cloud(7, xyz, point_step=20, row_pad=3, height=4),
           "float64 big-endian": lambda: make_cloud(7, xyz, point_step=32, bigendian=True, dtype="f8"),
           "odd frame id": lambda: make_cloud(7, xyz, frame_id="cam")}[kind]()
    raw = TYPESTORE.serialize_cdr(msg, CLOUD)
    same(pointcloud2_from_cdr(raw), decode_pointcloud2(msg))
    same(pointcloud2_from_cdr(raw, keep_nan=True), decode_pointcloud2(msg, keep_nan=True))


def test_scan_headers_the_decoder_reads_with_notes_give_the_same_notes() -> None:
    msg = make_scan(5, np.linspace(0.5, 2.0, 90, dtype=np.float32), angle_min=-1.0, increment=0.02)
    msg.range_min, msg.range_max = -1.0, float("inf")
    msg.intensities = np.arange(90, dtype=np.float32)
    msg.header.frame_id = "laser_ü"
    raw = TYPESTORE.serialize_cdr(msg, SCAN)
    scan = laserscan_from_cdr(raw)
    same(scan, decode_laserscan(TYPESTORE.deserialize_cdr(raw, SCAN)))  # the header's floats as recorded: float32
    assert len(scan.notes) == 2


def test_what_the_decoder_must_judge_is_left_to_it() -> None:
    """Anything but a sound little-endian scan gives None: the caller deserializes it and gets the decoder's
    own result or error."""
    good = make_scan(5, np.full(36, 1.0, dtype=np.float32), increment=0.1)
    zero_increment = make_scan(5, np.full(36, 1.0, dtype=np.float32), increment=0.0)
    bad_nanosec = make_scan(5, np.full(36, 1.0, dtype=np.float32))
    bad_nanosec.header.stamp.nanosec = 2_000_000_000
    raw = TYPESTORE.serialize_cdr(good, SCAN)
    big_endian = b"\x00\x00" + raw[2:]
    for case in (TYPESTORE.serialize_cdr(zero_increment, SCAN), TYPESTORE.serialize_cdr(bad_nanosec, SCAN)):
        assert laserscan_from_cdr(case) is None
    with pytest.raises(DecodeError):
        decode_laserscan(zero_increment)
    assert laserscan_from_cdr(big_endian) is None
    assert laserscan_from_cdr(raw[:-8]) is None  # cut inside the ranges
    too_many = bytearray(raw)
    struct.pack_into("<I", too_many, len(raw) - 4 - 4 * 36 - 4, 10**6)  # the ranges' count points past the end
    assert laserscan_from_cdr(bytes(too_many)) is None
    assert laserscan_from_cdr(b"") is None and pointcloud2_from_cdr(raw) is None


def test_the_readers_use_the_cdr_path_and_a_bad_message_still_costs_only_itself(tmp_path) -> None:
    from bagtools.dataset.scans import ScanStream
    from tests.conftest import write_bag

    messages = [("/scan", SCAN, 10**9 + i, make_scan(10**9 + i, np.full(90, 1.5, dtype=np.float32))) for i in range(4)]
    zero = make_scan(10**9 + 9, np.full(90, 1.5, dtype=np.float32), increment=0.0)
    path = write_bag(tmp_path / "bag", messages + [("/scan", SCAN, 10**9 + 9, zero)])
    with open_bag(path) as bag:
        stream = ScanStream(bag, "/scan", desc=None)
        got = list(stream)
    assert len(got) == 4 and stream.read == 5
    assert list(stream.skipped) == ["unusable header: LaserScan angle_increment is 0: all 90 beams would point the same way"]


def test_every_tf_message_of_the_fixtures_decodes_as_rosbags_decodes_it() -> None:
    n = 0
    for bag_path in (FIXTURES / "sim_lap_cloud_20s", FIXTURES / "sim_random_nocloud_20s"):
        with open_bag(bag_path) as bag:
            for raw in bag.raw_messages(["/tf", "/tf_static"]):
                assert tf_from_cdr(raw.raw) == tf_rows(bag.deserialize(raw).msg)
                n += 1
    assert n > 100


def test_tf_messages_of_odd_frame_ids_and_many_transforms_decode_the_same() -> None:
    T = TYPESTORE.types
    transforms = [make_tf(10**9 + i, "odom" * i or "m", "base_ü" + "x" * i, (i, -2.5, 1e-9), (0, 0, 0.6, 0.8)).transforms[0]
                  for i in range(6)]
    raw = TYPESTORE.serialize_cdr(T["tf2_msgs/msg/TFMessage"](transforms=transforms), "tf2_msgs/msg/TFMessage")
    assert tf_from_cdr(raw) == tf_rows(TYPESTORE.deserialize_cdr(raw, "tf2_msgs/msg/TFMessage"))
    assert len(tf_from_cdr(raw)) == 6
    assert tf_from_cdr(raw[:-9]) is None and tf_from_cdr(b"\x00\x00" + raw[2:]) is None


def test_every_odometry_message_of_the_fixtures_decodes_as_rosbags_decodes_it() -> None:
    from bagtools.io import decode_odometry
    from bagtools.io.cdr import odometry_from_cdr
    n = 0
    for bag_path in (FIXTURES / "sim_lap_cloud_20s", FIXTURES / "sim_random_nocloud_20s"):
        with open_bag(bag_path) as bag:
            for raw in bag.raw_messages(["/odom"]):
                same(odometry_from_cdr(raw.raw), decode_odometry(bag.deserialize(raw).msg))
                n += 1
    assert n > 100


@pytest.mark.parametrize("frame, child", [("odom", "base_footprint"), ("o", "b"), ("wörld" * 3, "base_ü" + "x" * 7)])
def test_odometry_of_odd_frame_ids_decodes_the_same_and_a_cut_message_is_left_to_rosbags(frame: str, child: str) -> None:
    from bagtools.io import decode_odometry
    from bagtools.io.cdr import odometry_from_cdr
    T = TYPESTORE.types
    rng = np.random.default_rng(3)
    header = T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=12, nanosec=345), frame_id=frame)
    pose = T["geometry_msgs/msg/PoseWithCovariance"](
        pose=T["geometry_msgs/msg/Pose"](position=T["geometry_msgs/msg/Point"](x=1.5, y=-2.0, z=0.25),
                                         orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.6, w=0.8)),
        covariance=rng.normal(size=36))
    twist = T["geometry_msgs/msg/TwistWithCovariance"](
        twist=T["geometry_msgs/msg/Twist"](linear=T["geometry_msgs/msg/Vector3"](x=0.3, y=0.0, z=0.0),
                                           angular=T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=-0.7)),
        covariance=rng.normal(size=36))
    msg = T["nav_msgs/msg/Odometry"](header=header, child_frame_id=child, pose=pose, twist=twist)
    raw = TYPESTORE.serialize_cdr(msg, "nav_msgs/msg/Odometry")
    same(odometry_from_cdr(raw), decode_odometry(TYPESTORE.deserialize_cdr(raw, "nav_msgs/msg/Odometry")))
    assert odometry_from_cdr(raw[:-1]) is None and odometry_from_cdr(b"\x00\x00" + raw[2:]) is None
