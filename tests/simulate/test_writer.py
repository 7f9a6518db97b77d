"""The simulated bag as rosbag2 files: metadata per distro, MCAP CRCs, type hashes, decoding by other readers."""

from __future__ import annotations

import struct
import zlib
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.records import Chunk, Footer
from mcap.stream_reader import StreamReader
from mcap_ros2.decoder import DecoderFactory
from rosbags.highlevel import AnyReader
from ruamel.yaml import YAML

from bagtools.io import open_bag
from bagtools_simulate.pipeline import SimConfig, simulate_bag
from bagtools_simulate.writer import TOPICS, MessageBuilder, typestore_for
from bagtools_simulate.writer.layout import FixedLayout

# RIHS01 hashes (REP 2011) as Jazzy publishes them, from outside rosbags: `ros2 topic info -v`
# output and type tables generated with ROS installations (std_msgs/String is also the hash in
# rmw_zenoh's documented key expressions). LaserScan: three independent projects agree.
KNOWN_RIHS01 = {
    "std_msgs/msg/String": "df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18",
    "tf2_msgs/msg/TFMessage": "e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087",
    "nav_msgs/msg/Odometry": "3cc97dc7fb7502f8714462c526d369e35b603cfc34d946e3f2eda2766dfec6e0",
    "sensor_msgs/msg/Imu": "7d9a00ff131080897a5ec7e26e315954b8eae3353c3f995c55faf71574000b5b",
    "sensor_msgs/msg/JointState": "a13ee3a330e346c9d87b5aa18d24e11690752bd33a0350f11c5882bc9179260e",
    "sensor_msgs/msg/CameraInfo": "b3dfd68ff46c9d56c80fd3bd4ed22c7a4ddce8c8348f2f59c299e73118e7e275",
    "sensor_msgs/msg/PointCloud2": "9198cabf7da3796ae6fe19c4cb3bdd3525492988c70522628af5daa124bae2b5",
    "sensor_msgs/msg/LaserScan": "64c191398013af96509d518dac71d5164f9382553fce5c1f8cca5be7924bd828",
}
DISTROS = ("humble", "jazzy")


@pytest.fixture(scope="module")
def bags(tmp_path_factory) -> dict[str, Path]:
    out = tmp_path_factory.mktemp("distros")
    return {d: simulate_bag(out / d, SimConfig(duration_s=3.0, cloud_size=(16, 12), ros_distro=d)).path
            for d in DISTROS}


def mcap_file(bag: Path) -> Path:
    [path] = bag.glob("*.mcap")
    return path


def test_default_distro_is_the_one_humble_and_jazzy_both_read():
    assert SimConfig().ros_distro == "humble"


def test_metadata_version_distro_and_qos_layout_per_distro(bags):
    yaml = YAML(typ="safe")
    humble = yaml.load(bags["humble"] / "metadata.yaml")["rosbag2_bagfile_information"]
    jazzy = yaml.load(bags["jazzy"] / "metadata.yaml")["rosbag2_bagfile_information"]
    assert (humble["version"], humble["ros_distro"]) == (5, "humble")
    assert (jazzy["version"], jazzy["ros_distro"]) == (9, "jazzy")
    assert jazzy["custom_data"] is None and "custom_data" not in humble
    for info in (humble, jazzy):
        assert info["storage_identifier"] == "mcap" and info["compression_mode"] == "" == info["compression_format"]
        assert info["message_count"] == sum(t["message_count"] for t in info["topics_with_message_count"])
        assert info["files"][0]["path"] == info["relative_file_paths"][0]
    for h, j in zip(humble["topics_with_message_count"], jazzy["topics_with_message_count"]):
        assert h["topic_metadata"]["name"] == j["topic_metadata"]["name"]
        # Humble: a YAML string with numbered policies; Jazzy: a YAML list with named ones.
        qos_h = h["topic_metadata"]["offered_qos_profiles"]
        qos_j = j["topic_metadata"]["offered_qos_profiles"]
        assert isinstance(qos_h, str) and isinstance(qos_j, list)
        [ph] = yaml.load(qos_h)
        [pj] = qos_j
        assert ph["history"] == 3 and pj["history"] == "unknown" and ph["depth"] == pj["depth"] == 0
        assert {1: "reliable", 2: "best_effort"}[ph["reliability"]] == pj["reliability"]
        assert {1: "transient_local", 2: "volatile"}[ph["durability"]] == pj["durability"]
        assert ph["deadline"] == pj["deadline"] == {"sec": 9223372036, "nsec": 854775807}
        assert "type_description_hash" not in h["topic_metadata"]
        assert j["topic_metadata"]["type_description_hash"].startswith("RIHS01_")
    latched = {t["topic_metadata"]["name"] for t in jazzy["topics_with_message_count"]
               if t["topic_metadata"]["offered_qos_profiles"][0]["durability"] == "transient_local"}
    assert latched == {"/tf_static", "/robot_description", "/simulation/world"}


@pytest.mark.parametrize("distro", DISTROS)
def test_mcap_channels_carry_qos_and_type_hash_and_rosbag2_metadata(bags, distro):
    with mcap_file(bags[distro]).open("rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert reader.get_header().profile == "ros2"
        ts = typestore_for(distro)
        for channel in summary.channels.values():
            msgtype = summary.schemas[channel.schema_id].name
            assert channel.message_encoding == "cdr" and summary.schemas[channel.schema_id].encoding == "ros2msg"
            assert msgtype == TOPICS[channel.topic][0]
            assert channel.metadata["topic_type_hash"] == ts.hash_rihs01(msgtype)
            qos = YAML(typ="safe").load(channel.metadata["offered_qos_profiles"])
            assert qos[0]["reliability"] in (("reliable", "best_effort") if distro == "jazzy" else (1, 2))
        [record] = [m for m in reader.iter_metadata() if m.name == "rosbag2"]
    meta = YAML(typ="safe").load(record.metadata["serialized_metadata"])
    assert meta["version"] == {"humble": 5, "jazzy": 9}[distro] and meta["ros_distro"] == distro
    on_disk = YAML(typ="safe").load(bags[distro] / "metadata.yaml")["rosbag2_bagfile_information"]
    assert meta == on_disk


def test_type_hashes_equal_the_published_ones():
    for distro in DISTROS:
        ts = typestore_for(distro)
        for msgtype, digest in KNOWN_RIHS01.items():
            assert ts.hash_rihs01(msgtype) == f"RIHS01_{digest}", (distro, msgtype)


@pytest.mark.parametrize("distro", DISTROS)
def test_chunk_and_summary_crcs_are_written_and_valid(bags, distro):
    data = mcap_file(bags[distro]).read_bytes()
    with mcap_file(bags[distro]).open("rb") as f:
        records = list(StreamReader(f, emit_chunks=True, validate_crcs=True).records)
    chunks = [r for r in records if isinstance(r, Chunk)]
    assert chunks and all(c.uncompressed_crc != 0 and c.compression == "zstd" for c in chunks)
    [footer] = [r for r in records if isinstance(r, Footer)]
    footer_at = len(data) - 8 - (1 + 8 + 8 + 8 + 4)
    assert footer.summary_crc != 0
    assert zlib.crc32(data[footer.summary_start:footer_at + 1 + 8 + 8 + 8]) == footer.summary_crc
    with mcap_file(bags[distro]).open("rb") as f:
        assert sum(1 for _ in make_reader(f, validate_crcs=True).iter_messages()) > 1000


def test_a_flipped_byte_in_a_chunk_is_caught_by_its_crc(bags, tmp_path):
    data = bytearray(mcap_file(bags["jazzy"]).read_bytes())
    with mcap_file(bags["jazzy"]).open("rb") as f:
        first = make_reader(f).get_summary().chunk_indexes[0]
    # flip a byte of the compressed records: zstd may still decode, the CRC must not match
    at = first.chunk_start_offset + first.chunk_length - 40
    data[at] ^= 0x01
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(bytes(data))
    with pytest.raises(Exception):
        with bad.open("rb") as f:
            for _ in make_reader(f, validate_crcs=True).iter_messages():
                pass


@pytest.mark.parametrize("distro", DISTROS)
def test_every_message_decodes_with_mcap_ros2_and_rosbags_and_bagtools(bags, distro):
    with mcap_file(bags[distro]).open("rb") as f:
        decoded = {}
        for _, channel, _, msg in make_reader(f, decoder_factories=[DecoderFactory()]).iter_decoded_messages():
            decoded[channel.topic] = decoded.get(channel.topic, 0) + 1
    with AnyReader([bags[distro]]) as reader:
        counts = {c.topic: c.msgcount for c in reader.connections}
        assert sum(1 for _ in reader.messages()) == reader.message_count
    assert decoded == {t: n for t, n in counts.items() if n}
    assert set(counts) == set(TOPICS) and counts["/clicked_point"] == 0  # no click in 3 s: the topic is still there
    with open_bag(bags[distro]) as bag:
        assert sum(1 for _ in bag.messages()) == sum(counts.values())


def test_batched_messages_are_byte_identical_to_one_by_one_serialization():
    mb = MessageBuilder(typestore_for("jazzy"))
    stamps = np.array([1_700_000_000_123_456_789, 1_700_000_007_000_000_001])
    poses = np.array([[1.0, -2.0, 0.3], [4.5, 0.25, -2.9]])
    v, w = np.array([0.1, -0.2]), np.array([0.5, 1.5])
    tf = mb.planar_tf_batch(stamps, "odom", "base_footprint", poses)
    odom = mb.odometry_batch(stamps, "odom", "base_footprint", poses, v, w)
    truth = mb.odometry_batch(stamps, "map", "base_footprint", poses, v, w, truth=True)
    for i in range(2):
        assert tf[i].tobytes() == mb.planar_tf(int(stamps[i]), "odom", "base_footprint", *poses[i])
        assert odom[i].tobytes() == mb.odometry(int(stamps[i]), "odom", "base_footprint", *poses[i], v[i], w[i])
        assert truth[i].tobytes() == mb.odometry(int(stamps[i]), "map", "base_footprint", *poses[i], v[i], w[i],
                                                 truth=True)
    imu = mb.imu_batch(stamps, "imu_link", np.array([[0, 0, 0.1, 0.995], [0, 0, -0.2, 0.98]]),
                       np.array([[1e-4, -2e-4, 0.5], [0, 0, 1.0]]), np.array([[0.1, 0.2, 9.8], [0, 0, 9.79]]),
                       (np.zeros(9), np.eye(3).ravel() * 4e-8, np.eye(3).ravel() * 2.89e-4))
    msg = mb.ts.deserialize_cdr(imu[1].tobytes(), "sensor_msgs/msg/Imu")
    assert msg.header.frame_id == "imu_link" and msg.header.stamp.sec == 1_700_000_007 and msg.header.stamp.nanosec == 1
    assert (msg.orientation.z, msg.angular_velocity.z, msg.linear_acceleration.z) == (-0.2, 1.0, 9.79)
    assert mb.ts.serialize_cdr(msg, "sensor_msgs/msg/Imu").tobytes() == imu[1].tobytes()


def test_fixed_layout_refuses_a_layout_that_depends_on_values():
    def serialize(values):
        return struct.pack("<d", values["x"]) + b"\x00" * (1 if values["x"] == 0 else 2)

    with pytest.raises(ValueError, match="fixed layout"):
        FixedLayout.probe(serialize, {"x": "f8"})


def test_bagtools_reports_a_chunk_whose_crc_does_not_match_as_damage(tmp_path):
    fixture = Path(__file__).resolve().parents[2] / "fixtures" / "sim_random_nocloud_20s"
    src = mcap_file(fixture)
    with src.open("rb") as f:
        chunks = make_reader(f).get_summary().chunk_indexes
    assert len(chunks) > 2
    chunk = chunks[1]
    data = bytearray(src.read_bytes())
    crc_at = chunk.chunk_start_offset + 1 + 8 + 8 + 8 + 8  # opcode, length, start, end, uncompressed size
    (crc,) = struct.unpack_from("<I", data, crc_at)
    assert crc != 0
    struct.pack_into("<I", data, crc_at, crc ^ 0x00010000)
    bag = tmp_path / "bag"
    bag.mkdir()
    (bag / src.name).write_bytes(bytes(data))
    (bag / "metadata.yaml").write_text((fixture / "metadata.yaml").read_text())
    with open_bag(bag) as reader:
        n = sum(1 for _ in reader.raw_messages())
        warnings = list(reader.warnings)
    assert any("damaged MCAP" in w and "checksum mismatch" in w for w in warnings), warnings
    with src.open("rb") as f:
        assert 0 < n < sum(1 for _ in make_reader(f).iter_messages())
