"""A rosbag2 writer for the simulator: one zstd-chunked MCAP file with CRCs, and metadata.yaml per distro.

Every ``--ros-distro`` gives a bag its own rosbag2 reads (see :mod:`bagtools_simulate.writer.metadata`):

- ``humble`` (the default): metadata version 5, which Humble *and* Jazzy read (Jazzy reads
  every version from 4 on). Channel QoS strings use Humble's numbered policies.
- ``jazzy``: the metadata exactly as Jazzy writes it, version 9 (QoS as a YAML list of named
  policies, ``type_description_hash``, ``ros_distro: jazzy``), which Humble cannot open.

The MCAP file has the layout of rosbag2's MCAP storage plugin: profile ``ros2``, one ``ros2msg``
schema per type (the concatenated message definitions), one ``cdr`` channel per topic whose
metadata holds ``offered_qos_profiles`` and ``topic_type_hash`` (the RIHS01 hash of REP 2011,
as Jazzy's plugin stores it; Humble's plugin ignores the key), message indexes, and a
``rosbag2`` metadata record with the bag's ``serialized_metadata`` (plus ``ROS_DISTRO``, which
newer readers take from Humble-era files). Chunks are zstd-compressed and every chunk and the
summary carry a CRC-32, as libmcap writes them by default and rosbag2 does when its storage
config says ``compression: Zstd`` and ``noChunkCRC: false`` (out of the box rosbag2 writes
uncompressed chunks without CRCs; readers accept both). Message log time is the receive time and publish time equals it.
"""

from __future__ import annotations

from pathlib import Path
from types import TracebackType
from typing import BinaryIO

from rosbags.typesys import Stores, get_typestore
from rosbags.typesys.store import Typestore

from bagtools.errors import BagtoolsError
from bagtools.outputs import is_own_output
from bagtools_simulate.writer.mcap_file import McapFileWriter
from bagtools_simulate.writer.metadata import BagInfo, OfferedQos, TopicInfo, metadata_yaml, qos_string, serialized_metadata

ROS_DISTROS = {"humble": Stores.ROS2_HUMBLE, "jazzy": Stores.ROS2_JAZZY}
DEFAULT_ROS_DISTRO = "humble"
MCAP_LIBRARY = "bagtools simulate"

_SENSOR = OfferedQos(reliable=False, transient_local=False)  # rclcpp's SensorDataQoS
_RELIABLE = OfferedQos(reliable=True, transient_local=False)
_LATCHED = OfferedQos(reliable=True, transient_local=True)  # tf2 static broadcaster, robot_state_publisher

# topic -> (message type, offered QoS).
TOPICS: dict[str, tuple[str, OfferedQos]] = {
    "/simulation/world": ("std_msgs/msg/String", _LATCHED),
    "/robot_description": ("std_msgs/msg/String", _LATCHED),
    "/tf_static": ("tf2_msgs/msg/TFMessage", _LATCHED),
    "/tf": ("tf2_msgs/msg/TFMessage", _RELIABLE),
    "/odom": ("nav_msgs/msg/Odometry", _RELIABLE),
    "/joint_states": ("sensor_msgs/msg/JointState", _RELIABLE),
    "/imu": ("sensor_msgs/msg/Imu", _SENSOR),
    "/ground_truth": ("nav_msgs/msg/Odometry", _RELIABLE),
    "/scan": ("sensor_msgs/msg/LaserScan", _SENSOR),
    "/camera/depth/camera_info": ("sensor_msgs/msg/CameraInfo", _SENSOR),
    "/camera/depth/points": ("sensor_msgs/msg/PointCloud2", _SENSOR),
    "/clicked_point": ("geometry_msgs/msg/PointStamped", _RELIABLE),
}


def is_rosbag2_output(path: Path) -> bool:
    """True when ``path`` is a directory ``simulate`` may replace with ``--force``: empty, or a bag it wrote.

    A bag ``simulate`` wrote carries bagtools' mark (:func:`bagtools.outputs.mark_own_output`) listing
    its files, and holds nothing else. A rosbag2 directory without the mark (``ros2 bag record``'s, or
    one a user added files to) is never replaced, whatever it holds.
    """
    return is_own_output(path, "simulate")


def typestore_for(ros_distro: str) -> Typestore:
    """The rosbags typestore of ``ros_distro`` (humble or jazzy)."""
    if ros_distro not in ROS_DISTROS:
        raise BagtoolsError(f"unknown ROS distro {ros_distro!r} (choose from {', '.join(ROS_DISTROS)})")
    return get_typestore(ROS_DISTROS[ros_distro])


class SimBagWriter:
    """Write serialized messages on the simulator's topics into a new rosbag2 directory ``path``.

    Use as a context manager; ``write(topic, log_time_ns, data)`` must be called in log-time
    order. On error the file is closed unfinished (the caller removes the directory).
    """

    def __init__(self, path: str | Path, ros_distro: str, topics: list[str]) -> None:
        self.path = Path(path)
        self.ros_distro = ros_distro
        self.typestore = typestore_for(ros_distro)
        unknown = [t for t in topics if t not in TOPICS]
        if unknown:
            raise ValueError(f"unknown simulator topics {unknown}")
        self.topics = list(topics)
        self.file_name = f"{self.path.name}.mcap"
        self.counts: dict[str, int] = {t: 0 for t in topics}
        self.type_hashes = {t: self.typestore.hash_rihs01(TOPICS[t][0]) for t in topics}
        self._stream: BinaryIO | None = None
        self._mcap: McapFileWriter | None = None
        self._channels: dict[str, int] = {}
        self._first_log_ns: int | None = None
        self._last_log_ns = -1

    def __enter__(self) -> SimBagWriter:
        self.path.mkdir(mode=0o755, parents=True)
        self._stream = (self.path / self.file_name).open("xb")
        self._mcap = McapFileWriter(self._stream, profile="ros2", library=MCAP_LIBRARY)
        schemas: dict[str, int] = {}
        for topic in self.topics:
            msgtype, offered = TOPICS[topic]
            if msgtype not in schemas:
                msgdef, _ = self.typestore.generate_msgdef(msgtype, ros_version=2)
                schemas[msgtype] = self._mcap.register_schema(msgtype, "ros2msg", msgdef.encode("utf-8"))
            self._channels[topic] = self._mcap.register_channel(
                topic, "cdr", schemas[msgtype],
                {"offered_qos_profiles": qos_string([offered], self.ros_distro), "topic_type_hash": self.type_hashes[topic]})
        return self

    def write(self, topic: str, log_time_ns: int, data: bytes) -> None:
        """Append one serialized message with bag (receive) time ``log_time_ns``."""
        if log_time_ns < self._last_log_ns:
            raise ValueError("messages must be written in log-time order")
        if self._mcap is None:
            raise ValueError("the bag is not open")
        if self._first_log_ns is None:
            self._first_log_ns = log_time_ns
        self._last_log_ns = log_time_ns
        self._mcap.add_message(self._channels[topic], log_time_ns, data)
        self.counts[topic] += 1

    def bag_info(self) -> BagInfo:
        """What metadata.yaml says of the messages written so far."""
        start = self._first_log_ns if self._first_log_ns is not None else 0
        topics = [TopicInfo(t, TOPICS[t][0], TOPICS[t][1], self.type_hashes[t], self.counts[t]) for t in self.topics]
        return BagInfo(self.ros_distro, self.file_name, start, max(0, self._last_log_ns - start), topics)

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None) -> None:
        stream, mcap = self._stream, self._mcap
        self._stream = self._mcap = None
        if stream is None or mcap is None:
            return
        try:
            if exc_type is None:
                info = self.bag_info()
                record = {"serialized_metadata": serialized_metadata(info)}
                if self.ros_distro == "humble":
                    record["ROS_DISTRO"] = "humble"
                mcap.add_metadata("rosbag2", record)
                mcap.finish()
        finally:
            stream.close()
        if exc_type is None:
            tmp = self.path / "metadata.yaml.tmp"
            tmp.write_text(metadata_yaml(self.bag_info()), encoding="utf-8")
            tmp.replace(self.path / "metadata.yaml")

