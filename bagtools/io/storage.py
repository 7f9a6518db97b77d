"""What ``ros2 bag info`` shows beyond the topics: storage id, bag size, ROS distro, serialization, QoS.

Read from what the bag records, in this order: a rosbag2 directory's
metadata.yaml; the MCAP file itself (header profile, the ``rosbag2`` metadata
record rosbag2 writes with the distro, each channel's ``offered_qos_profiles``);
the sqlite3 database's topics table (through rosbags); a ROS 1 bag's
connection headers (serialization ``ros1``, ``latching``). QoS profiles are
given in one form whatever version wrote them (rosbag2 stored the enums as
integers up to metadata version 8 and as names from 9): names such as
``keep_last``, ``reliable``, ``transient_local``; durations in integer
nanoseconds, or ``"infinite"``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from bagtools.io.mcap_source import McapScan

_HISTORY = ("system_default", "keep_last", "keep_all", "unknown")
_RELIABILITY = ("system_default", "reliable", "best_effort", "unknown", "best_available")
_DURABILITY = ("system_default", "transient_local", "volatile", "unknown", "best_available")
_LIVELINESS = ("system_default", "automatic", "manual_by_node", "manual_by_topic", "unknown", "best_available")
_ENUMS = {"history": _HISTORY, "reliability": _RELIABILITY, "durability": _DURABILITY, "liveliness": _LIVELINESS}
_DURATIONS = ("deadline", "lifespan", "liveliness_lease_duration")
_INFINITE = (9223372036, 854775807)


@dataclass(frozen=True)
class TopicStorage:
    """How one topic is stored: serialization format, offered QoS profiles (ROS 2) or latching (ROS 1)."""

    serialization_format: str
    offered_qos_profiles: list[dict] = field(default_factory=list)
    latching: bool | None = None


@dataclass(frozen=True)
class StorageDetails:
    """Storage id ('mcap', 'sqlite3', 'ros1'), the files and their size on disk, the ROS distro (None when the
    bag does not say), the ROS version, the metadata.yaml version, and each topic's storage."""

    storage_id: str
    files: list[str]
    size_bytes: int
    ros_distro: str | None
    ros_version: int
    metadata_version: int | None
    topics: dict[str, TopicStorage]

    @property
    def serialization_formats(self) -> list[str]:
        return sorted({t.serialization_format for t in self.topics.values()})


def normalize_qos(profile: Any) -> dict:
    """One QoS profile (a rosbags ``Qos``, or a dict with integer or named enums) in the names of rosbag2 v9."""
    if not isinstance(profile, dict):  # a rosbags Qos
        profile = {
            "history": int(profile.history.value), "depth": int(profile.depth),
            "reliability": int(profile.reliability.value), "durability": int(profile.durability.value),
            "deadline": {"sec": profile.deadline.sec, "nsec": profile.deadline.nsec},
            "lifespan": {"sec": profile.lifespan.sec, "nsec": profile.lifespan.nsec},
            "liveliness": int(profile.liveliness.value),
            "liveliness_lease_duration": {"sec": profile.liveliness_lease_duration.sec,
                                          "nsec": profile.liveliness_lease_duration.nsec},
            "avoid_ros_namespace_conventions": bool(profile.avoid_ros_namespace_conventions),
        }
    out: dict = {}
    for key, value in profile.items():
        if key in _ENUMS:
            names = _ENUMS[key]
            out[key] = names[value] if isinstance(value, int) and 0 <= value < len(names) else str(value).lower()
        elif key in _DURATIONS and isinstance(value, dict):
            sec, nsec = int(value.get("sec", 0)), int(value.get("nsec", 0))
            out[key] = "infinite" if (sec, nsec) == _INFINITE else sec * 10**9 + nsec
        else:
            out[key] = value
    return out


def qos_text(profiles: list[dict]) -> str:
    """A short description of offered QoS profiles, e.g. 'reliable transient_local keep_last(1)'."""
    parts = []
    for p in profiles:
        history = p.get("history", "")
        depth = f"({p['depth']})" if history == "keep_last" and "depth" in p else ""
        parts.append(" ".join(x for x in (p.get("reliability", ""), p.get("durability", ""), f"{history}{depth}") if x))
    unique = list(dict.fromkeys(parts))
    return " | ".join(unique)


def _load_yaml(text: str | bytes) -> Any:
    from ruamel.yaml import YAML

    return YAML(typ="safe", pure=True).load(text)


def _profiles(value: Any) -> list[dict]:
    """Offered QoS profiles from a metadata value: a YAML string (version <= 8, MCAP channels) or a list (9)."""
    try:
        loaded = _load_yaml(value) if isinstance(value, str) else value
    except Exception:  # an unreadable QoS string is no reason to fail the description
        return []
    if not isinstance(loaded, list):
        return []
    return [normalize_qos(p) for p in loaded if isinstance(p, dict)]


def _metadata_yaml(directory: Path) -> dict | None:
    path = directory / "metadata.yaml"
    if not path.is_file():
        return None
    try:
        info = _load_yaml(path.read_bytes())["rosbag2_bagfile_information"]
    except Exception:  # reported by the reader already
        return None
    return info if isinstance(info, dict) else None


def _mcap_distro(scan: McapScan) -> str | None:
    record = scan.metadata.get("rosbag2", {})
    if record.get("ROS_DISTRO"):
        return record["ROS_DISTRO"]
    text = record.get("serialized_metadata")
    if text:
        try:
            distro = _load_yaml(text).get("ros_distro")
        except Exception:
            distro = None
        return str(distro) if distro else None
    return None


def storage_details(bag: Any) -> StorageDetails:
    """The storage details of an open :class:`~bagtools.io.BagReader`."""
    path = Path(bag.path)
    directory = path.parent if path.name == "metadata.yaml" else path
    info = _metadata_yaml(directory) if directory.is_dir() else None
    sources = bag.storage_sources()
    scans = [s.scan for s in sources if hasattr(s, "scan")]
    files = [Path(p) for p in bag.storage_files()]
    storage_id = str(info.get("storage_identifier") or "") if info else ""
    if not storage_id:
        storage_id = {"mcap": "mcap", "sqlite3": "sqlite3", "ros1": "ros1", "carmen": "carmen"}.get(bag.kind, "")
        if not storage_id and files:
            storage_id = "mcap" if files[0].suffix == ".mcap" else "sqlite3"
    ros_version = 1 if storage_id in ("ros1", "carmen") or any(s.profile == "ros1" for s in scans) else 2
    distro = str(info["ros_distro"]) if info and info.get("ros_distro") else None
    distro = distro or next((d for s in scans if (d := _mcap_distro(s))), None)
    topics: dict[str, TopicStorage] = {}
    if info:  # metadata.yaml: serialization and QoS as rosbag2 recorded them
        for entry in info.get("topics_with_message_count") or []:
            meta = entry.get("topic_metadata") or {}
            name = meta.get("name")
            if name in bag.topics:
                topics[name] = TopicStorage(str(meta.get("serialization_format") or "cdr"),
                                            _profiles(meta.get("offered_qos_profiles")))
    for scan in scans:
        for channel in scan.channels.values():
            if channel.topic in bag.topics and channel.topic not in topics:
                topics[channel.topic] = TopicStorage(channel.message_encoding or "cdr",
                                                     _profiles(channel.metadata.get("offered_qos_profiles")))
    for source in sources:
        for conn in getattr(getattr(source, "reader", None), "connections", []):
            if conn.topic in topics or conn.topic not in bag.topics:
                continue
            ext = conn.ext
            if hasattr(ext, "latching"):
                topics[conn.topic] = TopicStorage("ros1", latching=bool(ext.latching))
            else:
                topics[conn.topic] = TopicStorage(ext.serialization_format,
                                                  [normalize_qos(q) for q in ext.offered_qos_profiles])
    version = int(info["version"]) if info and str(info.get("version", "")).isdigit() else None
    return StorageDetails(storage_id, [str(f) for f in files], sum(f.stat().st_size for f in files if f.exists()),
                          distro, ros_version, version, topics)
