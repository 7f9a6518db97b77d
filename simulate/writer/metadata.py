"""rosbag2 metadata as each ROS 2 distro writes it: ``metadata.yaml`` and the QoS strings of MCAP channels.

What rosbag2 writes (``rosbag2_storage`` ``yaml.hpp`` and ``qos.cpp``):

- Humble (rosbag2 0.15) writes metadata **version 5**: each topic's ``offered_qos_profiles`` is one
  YAML *string* holding a list of profiles with the policies as integers (history 3 = unknown,
  reliability 1 = reliable / 2 = best effort, durability 1 = transient local / 2 = volatile,
  liveliness 1 = automatic); no ``type_description_hash``, ``custom_data`` or ``ros_distro``.
  Humble's reader takes that string and nothing else, so it cannot open version 9.
- Jazzy (rosbag2 0.26) writes **version 9**: ``offered_qos_profiles`` is a YAML *list* with the
  policies by name (``unknown``, ``reliable``, ``transient_local``, ``automatic``), plus
  ``type_description_hash`` per topic, ``custom_data: ~`` and ``ros_distro: jazzy``. Jazzy reads
  every version from 4 on, so it reads Humble's version 5 as well.

The recorder stores the profile that discovery reports for each publisher: history unknown and
depth 0 (DDS does not announce them), reliability and durability as offered, infinite deadline,
lifespan and lease (``sec: 9223372036, nsec: 854775807``). The layout (key order, indentation,
the quoted QoS string) follows what yaml-cpp emits, so a user diffing against a recorded bag
sees the same shape. We add ``ros_distro: humble`` to version 5 too (rosbag2 ignores it below
version 8; it names the distro for people and for other readers).
"""

from __future__ import annotations

import json
from dataclasses import dataclass

METADATA_VERSION = {"humble": 5, "jazzy": 9}
_INFINITE = (9223372036, 854775807)  # RMW_DURATION_INFINITE as rosbag2 writes it


@dataclass(frozen=True)
class OfferedQos:
    """The QoS a publisher offers, as the recorder sees it: reliable or best effort, transient local or volatile."""

    reliable: bool
    transient_local: bool

    def fields(self, named: bool) -> list[tuple[str, str | int | tuple[int, int] | bool]]:
        """(key, value) in rosbag2's order; policies by name (version 9) or by number (up to version 8)."""
        if named:
            policies = ("unknown", "reliable" if self.reliable else "best_effort",
                        "transient_local" if self.transient_local else "volatile", "automatic")
        else:
            policies = (3, 1 if self.reliable else 2, 1 if self.transient_local else 2, 1)
        history, reliability, durability, liveliness = policies
        return [("history", history), ("depth", 0), ("reliability", reliability), ("durability", durability),
                ("deadline", _INFINITE), ("lifespan", _INFINITE), ("liveliness", liveliness),
                ("liveliness_lease_duration", _INFINITE), ("avoid_ros_namespace_conventions", False)]


def _scalar(value: str | int | bool) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    return str(value)


def qos_lines(profiles: list[OfferedQos], named: bool) -> list[str]:
    """A YAML block sequence of ``profiles`` (no indentation), as yaml-cpp dumps it."""
    lines: list[str] = []
    for profile in profiles:
        for i, (key, value) in enumerate(profile.fields(named)):
            lead = "- " if i == 0 else "  "
            if isinstance(value, tuple):
                lines += [f"{lead}{key}:", f"    sec: {value[0]}", f"    nsec: {value[1]}"]
            else:
                lines.append(f"{lead}{key}: {_scalar(value)}")
    return lines


def qos_string(profiles: list[OfferedQos], distro: str) -> str:
    """The ``offered_qos_profiles`` string of an MCAP channel as ``distro``'s storage plugin writes it."""
    return "\n".join(qos_lines(profiles, named=METADATA_VERSION[distro] >= 9))


@dataclass(frozen=True)
class TopicInfo:
    """One topic of the bag: name, type, offered QoS, RIHS01 type hash and message count."""

    name: str
    msgtype: str
    qos: OfferedQos
    type_hash: str
    message_count: int


@dataclass(frozen=True)
class BagInfo:
    """What metadata.yaml records about one single-file MCAP bag; times in int nanoseconds."""

    distro: str
    file_name: str
    start_ns: int
    duration_ns: int
    topics: list[TopicInfo]

    @property
    def message_count(self) -> int:
        """Messages over all topics."""
        return sum(t.message_count for t in self.topics)


def metadata_lines(info: BagInfo) -> list[str]:
    """The ``rosbag2_bagfile_information`` mapping (unindented) in ``info.distro``'s version and layout."""
    version = METADATA_VERSION[info.distro]
    lines = [f"version: {version}", "storage_identifier: mcap", "duration:", f"  nanoseconds: {info.duration_ns}",
             "starting_time:", f"  nanoseconds_since_epoch: {info.start_ns}", f"message_count: {info.message_count}",
             "topics_with_message_count:"]
    for topic in info.topics:
        lines += ["  - topic_metadata:", f"      name: {topic.name}", f"      type: {topic.msgtype}",
                  "      serialization_format: cdr"]
        if version >= 9:
            lines.append("      offered_qos_profiles:")
            lines += [f"        {line}" for line in qos_lines([topic.qos], named=True)]
        else:
            lines.append(f"      offered_qos_profiles: {json.dumps(qos_string([topic.qos], info.distro))}")
        if version >= 7:
            lines.append(f"      type_description_hash: {topic.type_hash}")
        lines.append(f"    message_count: {topic.message_count}")
    lines += ['compression_format: ""', 'compression_mode: ""', "relative_file_paths:", f"  - {info.file_name}",
              "files:", f"  - path: {info.file_name}", "    starting_time:",
              f"      nanoseconds_since_epoch: {info.start_ns}", "    duration:", f"      nanoseconds: {info.duration_ns}",
              f"    message_count: {info.message_count}"]
    if version >= 6:
        lines.append("custom_data: ~")
    lines.append(f"ros_distro: {info.distro}")
    return lines


def metadata_yaml(info: BagInfo) -> str:
    """The text of metadata.yaml."""
    return "\n".join(["rosbag2_bagfile_information:"] + [f"  {line}" for line in metadata_lines(info)]) + "\n"


def serialized_metadata(info: BagInfo) -> str:
    """The ``serialized_metadata`` value of the MCAP ``rosbag2`` metadata record (the same mapping, unwrapped)."""
    return "\n".join(metadata_lines(info))
