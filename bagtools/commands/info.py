"""What a bag holds: topics (type, count, frequency), time span and the tf tree.

``describe_bag`` reads the bag once: every message's bag time is counted per
topic without decoding, and only /tf and /tf_static are decoded for the tree.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from bagtools.errors import BagError
from bagtools.io import TfCollector, open_bag
from bagtools.io.storage import StorageDetails, qos_text, storage_details
from bagtools.progress import progress
from bagtools.tf.frames import FrameInfo, frame_infos, render_tree
from bagtools.tf.repair import tf_conflicts

#: info decodes the first this many messages of each topic (beyond tf, which it reads whole): damaged data is said.
DECODE_SAMPLE = 5


@dataclass(frozen=True)
class TopicSummary:
    """One topic: message type, count and mean frequency over its bag times."""

    name: str
    msgtype: str
    count: int
    frequency_hz: float
    first_ns: int
    last_ns: int


@dataclass(frozen=True)
class BagDescription:
    """Everything ``bagtools info`` reports about one bag."""

    path: str
    kind: str
    start_ns: int
    end_ns: int
    message_count: int
    topics: list[TopicSummary]
    frames: list[FrameInfo]
    warnings: list[str] = field(default_factory=list)
    storage: StorageDetails | None = None

    @property
    def duration_s(self) -> float:
        return (self.end_ns - self.start_ns) / 1e9

    def to_json(self) -> dict:
        """The description as JSON-able data (times in int ns and float s)."""
        return {
            "path": self.path,
            "kind": self.kind,
            "start_ns": self.start_ns,
            "end_ns": self.end_ns,
            "start_iso": _iso(self.start_ns),
            "end_iso": _iso(self.end_ns),
            "duration_s": self.duration_s,
            "message_count": self.message_count,
            **self._storage_json(),
            "topics": [self._topic_json(t) for t in self.topics],
            "tf_frames": [f.to_dict() for f in self.frames],
            "warnings": self.warnings,
        }


    def _storage_json(self) -> dict:
        s = self.storage
        if s is None:
            return {}
        return {"storage_id": s.storage_id, "bag_size_bytes": s.size_bytes, "files": s.files,
                "ros_distro": s.ros_distro, "ros_version": s.ros_version, "metadata_version": s.metadata_version,
                "serialization_format": ", ".join(s.serialization_formats)}

    def _topic_json(self, topic: TopicSummary) -> dict:
        out = dict(topic.__dict__)
        stored = self.storage.topics.get(topic.name) if self.storage else None
        if stored is not None:
            out["serialization_format"] = stored.serialization_format
            if stored.latching is None:
                out["offered_qos_profiles"] = stored.offered_qos_profiles
            else:
                out["latching"] = stored.latching
        return out


def _size_text(size_bytes: int) -> str:
    """Bytes as ros2 bag info shows them (KiB, MiB, GiB), with the exact count."""
    value, unit = float(size_bytes), "B"
    for next_unit in ("KiB", "MiB", "GiB", "TiB"):
        if value < 1024:
            break
        value, unit = value / 1024, next_unit
    return f"{value:.1f} {unit} ({size_bytes} bytes)" if unit != "B" else f"{size_bytes} B"


def _seconds(stamp_ns: int) -> str:
    """Exact seconds.nanoseconds of an int ns stamp (no float rounding)."""
    return f"{stamp_ns // 1_000_000_000}.{stamp_ns % 1_000_000_000:09d}"


def _iso(stamp_ns: int) -> str:
    return datetime.fromtimestamp(stamp_ns / 1e9, tz=UTC).isoformat(timespec="milliseconds")


def describe_bag(path: str | Path) -> BagDescription:
    """Read the bag at ``path`` once and describe it (raises :class:`~bagtools.errors.BagError`)."""
    with open_bag(path) as bag:
        collector = TfCollector()
        collector.check(bag)
        times: dict[str, list[int]] = {name: [] for name in bag.topics}
        undecodable: dict[str, list[str]] = {name: [] for name in bag.topics}  # problems of the sampled messages
        for raw in progress(bag.raw_messages(), total=bag.message_count, desc="reading"):
            times[raw.topic].append(raw.log_time_ns)
            if raw.topic in collector.topics:
                collector.add(bag.deserialize(raw))
            elif len(times[raw.topic]) <= DECODE_SAMPLE:  # are the topic's messages what their type says?
                try:
                    bag.deserialize(raw)
                except BagError as err:
                    undecodable[raw.topic].append(err.problem)
        damaged = [f"{bag.path}: {name}: {len(problems)} of its first {min(DECODE_SAMPLE, len(times[name]))} messages "
                   f"cannot be decoded (damaged data; commands skip such messages): {problems[0]}"
                   for name, problems in undecodable.items() if problems]
        topics = []
        for name, info in bag.topics.items():
            stamps = np.asarray(times[name], dtype=np.int64)
            span_s = (stamps.max() - stamps.min()) / 1e9 if stamps.size else 0.0
            freq = (stamps.size - 1) / span_s if stamps.size > 1 and span_s > 0 else 0.0
            topics.append(TopicSummary(name, info.msgtype, int(stamps.size), float(freq),
                                       int(stamps.min()) if stamps.size else 0, int(stamps.max()) if stamps.size else 0))
        dynamic, static = collector.arrays()
        return BagDescription(str(bag.path), bag.kind, bag.start_ns, bag.end_ns, sum(t.count for t in topics),
                              topics, frame_infos(dynamic, static), list(bag.warnings) + damaged + tf_conflicts(dynamic, static),
                              storage_details(bag))


def format_description(desc: BagDescription) -> str:
    """Human-readable text for ``bagtools info``."""
    lines = [
        f"path:       {desc.path}",
        f"format:     {'CARMEN log (text lines, read as ROS 1 messages)' if desc.kind == 'carmen' else desc.kind}",
        f"duration:   {desc.duration_s:.3f} s",
        f"start:      {_iso(desc.start_ns)} ({_seconds(desc.start_ns)} s)",
        f"end:        {_iso(desc.end_ns)} ({_seconds(desc.end_ns)} s)",
        f"messages:   {desc.message_count}",
    ]
    s = desc.storage
    if s is not None and desc.kind == "carmen":
        lines += [f"bag size:   {_size_text(s.size_bytes)}"]
    elif s is not None:
        distro = s.ros_distro or f"unknown (ROS {s.ros_version})"
        lines += [f"storage id: {s.storage_id}", f"bag size:   {_size_text(s.size_bytes)}", f"ROS distro: {distro}",
                  f"serialization format: {', '.join(s.serialization_formats) or 'unknown'}"]
    lines.append("")
    width = max((len(t.name) for t in desc.topics), default=5)
    type_width = max((len(t.msgtype) for t in desc.topics), default=4)
    lines.append(f"{'topic'.ljust(width)}  {'type'.ljust(type_width)}  {'count':>7}  {'freq (Hz)':>9}  QoS")
    for t in desc.topics:
        stored = s.topics.get(t.name) if s is not None else None
        qos = "" if stored is None else ("latched" if stored.latching else "") if stored.latching is not None \
            else qos_text(stored.offered_qos_profiles)
        lines.append(f"{t.name.ljust(width)}  {t.msgtype.ljust(type_width)}  {t.count:>7}  {t.frequency_hz:>9.2f}  {qos}"
                     .rstrip())
    lines.append("")
    if desc.frames:
        # Header stamps may be on another clock than bag time (simulation time),
        # so the tree's times are relative to the first tf stamp.
        dynamic_firsts = [f.first_ns for f in desc.frames if not f.is_static]
        origin_ns = min(dynamic_firsts) if dynamic_firsts else None
        origin = f"relative to the first tf stamp, {origin_ns / 1e9:.3f} s" if origin_ns is not None else "all static"
        lines.append(f"tf tree ({origin}):")
        lines.append(render_tree(desc.frames, origin_ns=origin_ns))
    else:
        lines.append("tf tree: no /tf or /tf_static data")
    return "\n".join(lines)
