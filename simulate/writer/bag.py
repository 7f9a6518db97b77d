"""A rosbag2 writer for the simulator: MCAP storage with zstd chunks, via rosbags' Writer.

``ros_distro="jazzy"`` writes rosbag2 metadata version 9; ``"humble"`` writes version 5, the
latest that Humble's rosbag2 reads (rosbags writes 8, and the metadata.yaml is then rewritten
as version 5, keeping the QoS strings identical to those stored in the MCAP channels).
"""

from __future__ import annotations

import json
from pathlib import Path
from types import TracebackType

from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime
from rosbags.rosbag2 import Writer
from rosbags.rosbag2.enums import CompressionFormat, CompressionMode, StoragePlugin
from rosbags.rosbag2.metadata import dump_qos_v8
from rosbags.typesys import Stores, get_typestore
from rosbags.typesys.store import Typestore

from bagtools.errors import BagtoolsError

ROS_DISTROS = {"humble": Stores.ROS2_HUMBLE, "jazzy": Stores.ROS2_JAZZY}
_INFINITE = QosTime(sec=9223372036, nsec=854775807)  # what rosbag2 records for "no deadline/lifespan"


def qos(reliable: bool, transient_local: bool, depth: int) -> Qos:
    """An offered QoS profile: keep-last ``depth``, reliable or best effort, transient-local or volatile."""
    return Qos(
        history=QosHistory.KEEP_LAST,
        depth=depth,
        reliability=QosReliability.RELIABLE if reliable else QosReliability.BEST_EFFORT,
        durability=QosDurability.TRANSIENT_LOCAL if transient_local else QosDurability.VOLATILE,
        deadline=_INFINITE,
        lifespan=_INFINITE,
        liveliness=QosLiveliness.AUTOMATIC,
        liveliness_lease_duration=_INFINITE,
        avoid_ros_namespace_conventions=False,
    )


# topic -> (message type, offered QoS): tf2's static broadcaster latches (transient local,
# depth 1); sensors use the sensor-data profile (best effort).
TOPICS: dict[str, tuple[str, Qos]] = {
    "/simulation/world": ("std_msgs/msg/String", qos(True, True, 1)),
    "/tf_static": ("tf2_msgs/msg/TFMessage", qos(True, True, 1)),
    "/tf": ("tf2_msgs/msg/TFMessage", qos(True, False, 100)),
    "/odom": ("nav_msgs/msg/Odometry", qos(True, False, 10)),
    "/ground_truth": ("nav_msgs/msg/Odometry", qos(True, False, 10)),
    "/scan": ("sensor_msgs/msg/LaserScan", qos(False, False, 5)),
    "/camera/depth/points": ("sensor_msgs/msg/PointCloud2", qos(False, False, 5)),
    "/clicked_point": ("geometry_msgs/msg/PointStamped", qos(True, False, 10)),
}


def is_rosbag2_output(path: Path) -> bool:
    """True when ``path`` is a directory ``simulate`` may replace with ``--force``: empty, or a rosbag2
    directory of metadata.yaml and .mcap files only (a bag it wrote), nothing else of the user's."""
    entries = list(path.iterdir())
    if not entries:
        return True
    names = {p.name for p in entries}
    return ("metadata.yaml" in names and all(p.is_file() and not p.is_symlink() for p in entries)
            and all(n == "metadata.yaml" or n.endswith(".mcap") for n in names))


def typestore_for(ros_distro: str) -> Typestore:
    """The rosbags typestore of ``ros_distro`` (humble or jazzy)."""
    if ros_distro not in ROS_DISTROS:
        raise BagtoolsError(f"unknown ROS distro {ros_distro!r} (choose from {', '.join(ROS_DISTROS)})")
    return get_typestore(ROS_DISTROS[ros_distro])


class SimBagWriter:
    """Write serialized messages on the simulator's topics into a new rosbag2 directory ``path``.

    Use as a context manager; ``write(topic, log_time_ns, data)`` must be called in log-time
    order. On error the storage is aborted (the caller removes the directory).
    """

    def __init__(self, path: str | Path, ros_distro: str, topics: list[str]) -> None:
        self.path = Path(path)
        self.ros_distro = ros_distro
        self.typestore = typestore_for(ros_distro)
        unknown = [t for t in topics if t not in TOPICS]
        if unknown:
            raise ValueError(f"unknown simulator topics {unknown}")
        self.topics = list(topics)
        self._writer = Writer(self.path, version=8 if ros_distro == "humble" else 9, storage_plugin=StoragePlugin.MCAP)
        self._writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
        self._connections: dict = {}
        self.counts: dict[str, int] = {t: 0 for t in topics}
        self._last_log_ns = -1

    def __enter__(self) -> SimBagWriter:
        self._writer.open()
        for topic in self.topics:
            msgtype, profile = TOPICS[topic]
            self._connections[topic] = self._writer.add_connection(
                topic, msgtype, typestore=self.typestore, offered_qos_profiles=[profile]
            )
        return self

    def write(self, topic: str, log_time_ns: int, data: bytes) -> None:
        """Append one serialized message with bag (log) time ``log_time_ns``."""
        if log_time_ns < self._last_log_ns:
            raise ValueError("messages must be written in log-time order")
        self._last_log_ns = log_time_ns
        self._writer.write(self._connections[topic], int(log_time_ns), data)
        self.counts[topic] += 1

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None) -> None:
        self._writer.__exit__(exc_type, exc, tb)
        if exc_type is None and self.ros_distro == "humble":
            self._rewrite_metadata_v5()

    def _rewrite_metadata_v5(self) -> None:
        """Rewrite metadata.yaml in the version-5 layout Humble reads (same counts and times)."""
        w = self._writer
        mcap_name = f"{self.path.name}.mcap"
        duration = max(0, w.max_timestamp - w.min_timestamp)
        total = sum(w.counts.values())
        lines = [
            "rosbag2_bagfile_information:",
            "  version: 5",
            "  storage_identifier: mcap",
            "  duration:",
            f"    nanoseconds: {duration}",
            "  starting_time:",
            f"    nanoseconds_since_epoch: {w.min_timestamp}",
            f"  message_count: {total}",
            "  topics_with_message_count:",
        ]
        for conn in w.connections:
            lines += [
                "    - topic_metadata:",
                f"        name: {conn.topic}",
                f"        type: {conn.msgtype}",
                "        serialization_format: cdr",
                f"        offered_qos_profiles: {json.dumps(dump_qos_v8(conn.ext.offered_qos_profiles))}",
                f"      message_count: {w.counts[conn.id]}",
            ]
        lines += [
            '  compression_format: ""',
            '  compression_mode: ""',
            "  relative_file_paths:",
            f"    - {mcap_name}",
            "  files:",
            f"    - path: {mcap_name}",
            "      starting_time:",
            f"        nanoseconds_since_epoch: {w.min_timestamp}",
            "      duration:",
            f"        nanoseconds: {duration}",
            f"      message_count: {total}",
        ]
        tmp = self.path / "metadata.yaml.tmp"
        tmp.write_text("\n".join(lines) + "\n", encoding="utf-8")
        tmp.replace(self.path / "metadata.yaml")
