"""The sources a :class:`~bagtools.io.reader.BagReader` reads through: rosbags' AnyReader for ROS 1 and sqlite3
bags (:class:`AnySource`, reading past a damaged ROS 1 chunk), :mod:`bagtools.io.mcap_source` for MCAP files
(:class:`McapSource`, whatever is readable, with a typestore built from the file's schemas), and several storage
files of one bag merged by bag time (:class:`MergedSource`). Each gives topics, a time span and raw records."""

from __future__ import annotations

import heapq
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

from rosbags.highlevel import AnyReader
from rosbags.interfaces import Connection
from rosbags.rosbag1 import ReaderError as Rosbag1ReaderError
from rosbags.typesys import Stores, get_types_from_idl, get_types_from_msg, get_typestore

from bagtools.errors import BagtoolsError
from bagtools.io.mcap_messages import iter_segments
from bagtools.io.mcap_source import McapScan, scan_mcap
from bagtools.io.records import RawRecord, TopicInfo


class AnySource:
    """Messages through rosbags' AnyReader (every complete bag)."""

    #: How read_damage is said (MCAP's source says "damaged MCAP").
    damage_kind = "damaged ROS 1 bag"

    def __init__(self, paths: list[Path]) -> None:
        self.path = paths[0]
        # the default types serve only a rosbag2 file that stores none (a ROS 1 bag always carries its own):
        # building them costs a third of `info`'s start, so a ROS 1 bag goes without
        ros1 = all(p.suffix == ".bag" for p in paths)
        self.reader = AnyReader(paths, default_typestore=None if ros1 else get_typestore(Stores.ROS2_HUMBLE))
        self.reader.open()
        self.read_damage: list[str] = []  # damaged ROS 1 chunks read past: what was skipped
        self.topics = _topics_of(self.reader.connections, lambda c: c.msgcount)
        self.cdr_topics = {c.topic for c in self.reader.connections
                           if getattr(c.ext, "serialization_format", None) == "cdr"}  # rosbag2's; ROS 1 has its own
        self.start_ns = self.reader.start_time
        self.end_ns = self.reader.end_time - 1  # rosbags' end time is exclusive (last + 1 ns)

    def raw(self, topics: set[str] | None) -> Iterator[RawRecord]:
        conns = [c for c in self.reader.connections if topics is None or c.topic in topics]
        if not conns:
            return
        start = None
        while True:
            n = 0
            try:
                for conn, t_ns, raw in self.reader.messages(connections=conns, start=start):
                    n += 1
                    yield RawRecord(conn.topic, conn.msgtype, t_ns, raw, getattr(conn.ext, "callerid", None) or "")
                return
            except Rosbag1ReaderError:
                start = self._past_damaged_chunk(conns, start, n)
                if start is None:
                    raise

    def _past_damaged_chunk(self, conns: list[Connection], start: int | None, n_read: int) -> int | None:
        """Where to read on after a damaged chunk of a ROS 1 bag: the stamp after the last message of the chunk
        that holds the next message (the ``n_read``-th of ``conns`` from ``start``), whose reading failed; what is
        skipped is added to ``read_damage``. None when this is not one ROS 1 file (a rosbag2 file's damage ends the
        read) or no message is left after the chunk. A ROS 1 bag's index lies at its end, apart from the chunks:
        every chunk can be found without reading the ones before it."""
        readers = self.reader.readers
        if len(readers) != 1 or not hasattr(readers[0], "chunk_infos"):
            return None
        indexes = readers[0].indexes
        entries = [e for e in heapq.merge(*(indexes[c.id] for c in conns)) if start is None or e.time >= start]
        if n_read >= len(entries):
            return None
        failed = entries[n_read]
        end = max(e.time for index in indexes.values() for e in index if e.chunk_pos == failed.chunk_pos)
        skipped = [e for e in entries[n_read:] if e.time <= end]
        if len(skipped) == len(entries) - n_read:  # nothing after it: the read ends here, and says so
            return None
        self.read_damage.append(f"the chunk at byte {failed.chunk_pos} cannot be read: {len(skipped)} message(s) "
                                f"over {(end - failed.time) / 1e9:.1f} s skipped, read on past it")
        return end + 1

    def deserializer(self) -> Callable[[RawRecord], Any]:
        return lambda rec: self.reader.deserialize(rec.raw, rec.msgtype)

    @property
    def typestore(self) -> Any:
        return self.reader.typestore

    def close(self) -> None:
        self.reader.close()


class MergedSource:
    """Several storage files of one bag, each read by its own source and merged by bag time."""

    def __init__(self, parts: list[Any]) -> None:
        self.parts = parts
        counts: dict[str, TopicInfo] = {}
        for part in self.parts:
            for name, info in part.topics.items():
                prev = counts.get(name)
                counts[name] = TopicInfo(name, info.msgtype, info.count + (prev.count if prev else 0))
        self.topics = counts
        self.start_ns = min(p.start_ns for p in self.parts)
        self.end_ns = max(p.end_ns for p in self.parts)
        self.cdr_topics = set.intersection(*(p.cdr_topics | (set(counts) - set(p.topics)) for p in self.parts))

    def raw(self, topics: set[str] | None) -> Iterator[RawRecord]:
        return heapq.merge(*(p.raw(topics) for p in self.parts), key=lambda r: r.log_time_ns)

    def deserializer(self) -> Callable[[RawRecord], Any]:
        # All parts come from one recording, so their type definitions agree.
        return self.parts[0].deserializer()

    @property
    def typestore(self) -> Any:
        return self.parts[0].typestore

    def close(self) -> None:
        for part in self.parts:
            part.close()


class McapSource:
    """An MCAP file read with :mod:`bagtools.io.mcap_source`: whatever is readable, in log-time order.

    ``warnings`` says what was lost (a truncation, damaged chunks, topics whose
    message definition cannot be parsed); ``message_count`` counts what can be read.
    """

    def __init__(self, path: Path) -> None:
        self.path = path
        self.scan = scan_mcap(path, verify=False)
        self.warnings: list[str] = []
        self.read_damage: list[str] = []  # damage met while reading chunks the scan did not check
        self.typestore, unusable, garbled = _typestore_from_schemas(self.scan)
        if garbled and not self.scan.verified:  # the summary's schemas may be the damaged copy: read the data's
            self.scan = scan_mcap(path, verify=True)
            self.typestore, unusable, garbled = _typestore_from_schemas(self.scan)
        self.topics: dict[str, TopicInfo] = {}
        self._channels: dict[int, tuple[str, str]] = {}  # channel id -> (topic, msgtype)
        self.cdr_topics: set[str] = set()  # topics whose every channel is CDR-encoded
        skipped: dict[str, int] = {}
        for channel_id in sorted(set(self.scan.counts) | set(self.scan.channels)):  # topics with 0 messages too
            count = self.scan.counts.get(channel_id, 0)
            channel = self.scan.channels.get(channel_id)
            schema = self.scan.schemas.get(channel.schema_id) if channel is not None else None
            if channel is None or schema is None or schema.name in unusable:
                name = channel.topic if channel is not None else f"channel {channel_id}"
                skipped[name] = skipped.get(name, 0) + count
                continue
            self._channels[channel_id] = (channel.topic, schema.name)
            if channel.message_encoding == "cdr":
                self.cdr_topics.add(channel.topic)
            prev = self.topics.get(channel.topic)
            self.topics[channel.topic] = TopicInfo(channel.topic, schema.name, count + (prev.count if prev else 0))
        self.cdr_topics -= {ch.topic for ch in self.scan.channels.values() if ch.message_encoding != "cdr"}
        self.message_count = sum(t.count for t in self.topics.values())
        self.start_ns = self.scan.start_ns or 0
        self.end_ns = self.scan.end_ns or 0
        self._warn(unusable, skipped)

    def _warn(self, unusable: dict[str, str], skipped: dict[str, int]) -> None:
        scan = self.scan
        if not scan.complete and scan.cut_at_byte is not None:
            self.warnings.append(f"{self.path}: truncated MCAP (no footer; cut at byte {scan.cut_at_byte}): "
                                 f"recovered {scan.message_count} messages before the cut")
        if scan.damage:
            more = f" (and {len(scan.damage) - 1} more)" if len(scan.damage) > 1 else ""
            lost = f", {scan.lost_messages} messages known to be lost" if scan.lost_messages else ""
            self.warnings.append(f"{self.path}: damaged MCAP: {scan.damage[0]}{more}; "
                                 f"read {scan.message_count} messages{lost}")
        for topic, count in skipped.items():
            why = next(iter(unusable.values()), "no schema or channel record")
            self.warnings.append(f"{self.path}: {topic}: message definition unusable ({why}); "
                                 f"its {count} messages are skipped")

    def raw(self, topics: set[str] | None) -> Iterator[RawRecord]:
        wanted = {cid for cid, (topic, _) in self._channels.items() if topics is None or topic in topics}
        if not wanted:
            return
        for message in iter_segments(self.path, self.scan, wanted, self.read_damage):
            topic, msgtype = self._channels[message.channel_id]
            yield RawRecord(topic, msgtype, message.log_time, message.data)

    def deserializer(self) -> Callable[[RawRecord], Any]:
        return lambda rec: self.typestore.deserialize_cdr(bytes(rec.raw), rec.msgtype)

    def close(self) -> None:
        pass


def _typestore_from_schemas(scan: McapScan) -> tuple[Any, dict[str, str], tuple[str, ...]]:
    """A typestore with the MCAP's schemas (ROS 2 Humble types as fallback), and the unusable ones.

    Returns (typestore, {schema name: why it is unusable}, the names of the schemas
    whose text does not parse, usable or not); one garbled schema does not stop the
    others from being read. Cached by the schemas' text, as
    commands open the same bag more than once (building one costs ~0.1 s).
    """
    key = tuple(sorted((s.name, s.encoding, bytes(s.data)) for s in scan.schemas.values()))
    return _typestore_for(key)


@lru_cache(maxsize=8)
def _typestore_for(key: tuple[tuple[str, str, bytes], ...]) -> tuple[Any, dict[str, str], tuple[str, ...]]:
    typestore = get_typestore(Stores.ROS2_HUMBLE)
    unusable: dict[str, str] = {}
    garbled: list[str] = []
    schemas = [_SchemaText(name, encoding, data) for name, encoding, data in key]
    for schema in schemas:
        try:
            types = _types_of_schema(schema)
            typestore.register(types)
        except Exception as err:  # rosbags' parsers raise several types on garbage text
            garbled.append(schema.name)
            if schema.name not in typestore.types:
                unusable[schema.name] = f"{type(err).__name__}: {' '.join(str(err).split())[:120]}"
    for schema in schemas:
        if schema.name not in typestore.types and schema.name not in unusable:
            unusable[schema.name] = "unknown message type"
    return typestore, unusable, tuple(garbled)


@dataclass(frozen=True)
class _SchemaText:
    name: str
    encoding: str
    data: bytes


def _types_of_schema(schema: Any) -> dict[str, Any]:
    text = schema.data.decode("utf-8")
    if schema.encoding == "ros2msg":
        return dict(get_types_from_msg(text, schema.name))
    if schema.encoding == "ros2idl":
        types: dict[str, Any] = {}
        sep = "=" * 80 + "\n"
        parts = text.split(sep)[1:] if text.startswith(f"{sep}IDL: ") else [f"IDL: x\n{text}"]
        for part in parts:
            types.update(get_types_from_idl(part.split("\n", 1)[1]))
        return types
    raise BagtoolsError(f"schema encoding {schema.encoding!r} is not a ROS 2 message definition")


def _topics_of(connections: Iterable[Connection], count: Callable[[Connection], int]) -> dict[str, TopicInfo]:
    topics: dict[str, TopicInfo] = {}
    for conn in connections:
        prev = topics.get(conn.topic)
        topics[conn.topic] = TopicInfo(conn.topic, conn.msgtype, count(conn) + (prev.count if prev else 0))
    return topics
