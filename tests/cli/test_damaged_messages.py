"""Messages whose bytes are not what their type says (a db3 whose scan blobs are garbage): every command says so.

``info`` decodes the first messages of each topic and warns; a command that finds no usable scan says that its
messages could not be decoded, instead of "no scans" alone (issue #42: these exited 0, or blamed nothing).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from tests.cli.test_data_loss import run

N_SCANS = 12


@pytest.fixture(scope="module")
def garbage_scans(tmp_path_factory) -> Path:
    """A rosbag2 sqlite3 bag: a LaserScan topic whose every message is random bytes, a sound /odom and /tf."""
    bag = tmp_path_factory.mktemp("damaged") / "garbage_scans"
    store = get_typestore(Stores.ROS2_HUMBLE)
    Odometry = store.types["nav_msgs/msg/Odometry"]
    msg_types = store.types
    rng = np.random.default_rng(3)
    with Writer(bag, version=8, storage_plugin=StoragePlugin.SQLITE3) as writer:
        scan = writer.add_connection("/scan", "sensor_msgs/msg/LaserScan", typestore=store)
        odom = writer.add_connection("/odom", "nav_msgs/msg/Odometry", typestore=store)
        tf = writer.add_connection("/tf", "tf2_msgs/msg/TFMessage", typestore=store)
        for k in range(N_SCANS):
            t = 1_700_000_000_000_000_000 + k * 200_000_000
            writer.write(scan, t, rng.integers(0, 256, 900, dtype=np.uint8).tobytes())
            header = msg_types["std_msgs/msg/Header"](stamp=msg_types["builtin_interfaces/msg/Time"](
                sec=t // 10**9, nanosec=t % 10**9), frame_id="odom")
            pose = msg_types["geometry_msgs/msg/PoseWithCovariance"](pose=msg_types["geometry_msgs/msg/Pose"](
                position=msg_types["geometry_msgs/msg/Point"](x=0.1 * k, y=0.0, z=0.0),
                orientation=msg_types["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0)),
                covariance=np.zeros(36))
            twist = msg_types["geometry_msgs/msg/TwistWithCovariance"](twist=msg_types["geometry_msgs/msg/Twist"](
                linear=msg_types["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0),
                angular=msg_types["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)), covariance=np.zeros(36))
            writer.write(odom, t, store.serialize_cdr(Odometry(header=header, child_frame_id="base_link", pose=pose,
                                                              twist=twist), "nav_msgs/msg/Odometry"))
            transform = msg_types["geometry_msgs/msg/TransformStamped"](header=header, child_frame_id="base_link",
                transform=msg_types["geometry_msgs/msg/Transform"](
                    translation=msg_types["geometry_msgs/msg/Vector3"](x=0.1 * k, y=0.0, z=0.0),
                    rotation=pose.pose.orientation))
            writer.write(tf, t, store.serialize_cdr(msg_types["tf2_msgs/msg/TFMessage"](transforms=[transform]),
                                                    "tf2_msgs/msg/TFMessage"))
    return bag


def test_info_says_a_topic_whose_messages_cannot_be_decoded(garbage_scans: Path, capsys) -> None:
    code, out, err = run(["info", str(garbage_scans)], capsys)
    assert code == 0 and "/scan" in out
    lines = [line for line in err.splitlines() if "/scan" in line]
    assert len(lines) == 1 and "5 of its first 5 messages cannot be decoded" in lines[0], err
    assert "/odom" not in err and "/tf" not in err  # the sound topics are not blamed


@pytest.mark.parametrize("argv", [
    ["slam", "{bag}", "--out", "{out}"],
    ["ndt-odom", "{bag}", "--out", "{out}"],
    ["map-cloud", "{bag}", "--topic", "/scan", "--frame", "odom", "--out", "{out}"],
])
def test_a_command_without_a_usable_scan_says_the_scans_cannot_be_decoded(argv: list[str], garbage_scans: Path,
                                                                            tmp_path: Path, capsys) -> None:
    out = tmp_path / "out"
    code, _, err = run([a.format(bag=garbage_scans, out=out) for a in argv], capsys)
    last = err.strip().splitlines()[-1]
    assert code == 2 and last.startswith(f"bagtools: {garbage_scans}"), err
    assert f"{N_SCANS} of its messages cannot be decoded, the bag is damaged" in last, last
    assert "Traceback" not in err and not out.exists()


def test_a_damaged_zstd_compressed_rosbag2_file_is_said_not_an_internal_error(tmp_path: Path, capsys) -> None:
    """A rosbag2 whose storage file is zstd-compressed whole (``ros2 bag record --compression-mode file``), with
    bytes flipped: one line saying it cannot be read, not "internal error (ZstdError ...) please report"."""
    from rosbags.rosbag2 import CompressionFormat, CompressionMode

    bag = tmp_path / "compressed"
    store = get_typestore(Stores.ROS2_HUMBLE)
    String = store.types["std_msgs/msg/String"]
    rng = np.random.default_rng(5)
    writer = Writer(bag, version=8, storage_plugin=StoragePlugin.SQLITE3)
    writer.set_compression(CompressionMode.FILE, CompressionFormat.ZSTD)
    with writer:
        conn = writer.add_connection("/chatter", "std_msgs/msg/String", typestore=store)
        for k in range(400):  # random text: the compressed file is large enough to damage in its middle
            text = "".join(chr(c) for c in rng.integers(97, 123, 200))
            writer.write(conn, 1_700_000_000_000_000_000 + k * 10**8, store.serialize_cdr(String(data=text),
                                                                                         "std_msgs/msg/String"))
    (compressed,) = bag.glob("*.zstd")
    data = bytearray(compressed.read_bytes())
    start = len(data) * 9 // 10  # flipped near the end: zstd's own check says the data is corrupt
    data[start:start + 2000] = bytes(b ^ 0xFF for b in data[start:start + 2000])
    compressed.write_bytes(bytes(data))
    code, _, err = run(["info", str(bag)], capsys)
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1 and lines[0].startswith(f"bagtools: {bag}: cannot read"), err
    assert "internal error" not in err, err
