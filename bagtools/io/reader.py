"""One reader facade over every bag format a user may have.

``open_bag(path)`` accepts a rosbag2 directory (MCAP or sqlite3 storage, with or
without metadata.yaml), a bare ``.mcap`` or ``.db3`` file, or a ROS 1 ``.bag``,
and yields time-ordered records. Formats are told apart by their magic bytes,
not by trust in the suffix. Two failure modes of real bags are handled here:

- a truncated MCAP (no footer) is read up to the cut by
  :mod:`bagtools.io.mcap_recovery`, with a warning saying how many messages were
  recovered;
- a rosbag2 directory whose metadata.yaml promises messages that rosbags then
  does not yield (seen with rosbags 0.11.9 when the metadata's QoS differs from
  the storage file's) is re-read from its storage files directly.
"""

from __future__ import annotations

import heapq
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from rosbags.highlevel import AnyReader, AnyReaderError
from rosbags.interfaces import Connection
from rosbags.typesys import Stores, get_types_from_idl, get_types_from_msg, get_typestore

from bagtools.errors import BagError, TopicError
from bagtools.io.mcap_recovery import RecoveredStream, iter_recovered

MCAP_MAGIC = b"\x89MCAP0\r\n"
ROS1_MAGIC = b"#ROSBAG V2.0"
SQLITE_MAGIC = b"SQLite format 3\x00"
_KIND_BY_MAGIC = {MCAP_MAGIC: "mcap", ROS1_MAGIC: "ros1", SQLITE_MAGIC: "sqlite3"}
_SUFFIX_BY_KIND = {"mcap": ".mcap", "ros1": ".bag", "sqlite3": ".db3"}
_ROSBAGS_ERRORS = (AnyReaderError, OSError, KeyError, ValueError, TypeError, AssertionError)


@dataclass(frozen=True)
class TopicInfo:
    """A topic of a bag: its name, ROS 2 style message type and message count."""

    name: str
    msgtype: str
    count: int


@dataclass(frozen=True, slots=True)
class RawRecord:
    """One serialized message: topic, type, bag (log) time in ns and the raw bytes."""

    topic: str
    msgtype: str
    log_time_ns: int
    raw: bytes | memoryview


@dataclass(frozen=True, slots=True)
class Record:
    """One deserialized message (a rosbags message object) with its bag time in ns."""

    topic: str
    msgtype: str
    log_time_ns: int
    msg: Any


def sniff_kind(path: Path) -> str | None:
    """Return 'mcap', 'ros1' or 'sqlite3' from a file's magic bytes, or None."""
    with path.open("rb") as f:
        head = f.read(16)
    for magic, kind in _KIND_BY_MAGIC.items():
        if head.startswith(magic):
            return kind
    return None


class _AnySource:
    """Messages through rosbags' AnyReader (every complete bag)."""

    def __init__(self, paths: list[Path]) -> None:
        self.reader = AnyReader(paths, default_typestore=get_typestore(Stores.ROS2_HUMBLE))
        self.reader.open()
        self.topics = _topics_of(self.reader.connections, lambda c: c.msgcount)
        self.start_ns = self.reader.start_time
        self.end_ns = self.reader.end_time - 1  # rosbags' end time is exclusive (last + 1 ns)

    def raw(self, topics: set[str] | None) -> Iterator[RawRecord]:
        conns = [c for c in self.reader.connections if topics is None or c.topic in topics]
        if not conns:
            return
        for conn, t_ns, raw in self.reader.messages(connections=conns):
            yield RawRecord(conn.topic, conn.msgtype, t_ns, raw)

    def deserializer(self) -> Callable[[RawRecord], Any]:
        return lambda rec: self.reader.deserialize(rec.raw, rec.msgtype)

    def close(self) -> None:
        self.reader.close()


class _MergedSource:
    """Several complete storage files read directly and merged by bag time."""

    def __init__(self, paths: list[Path]) -> None:
        self.parts = [_AnySource([p]) for p in paths]
        counts: dict[str, TopicInfo] = {}
        for part in self.parts:
            for name, info in part.topics.items():
                prev = counts.get(name)
                counts[name] = TopicInfo(name, info.msgtype, info.count + (prev.count if prev else 0))
        self.topics = counts
        self.start_ns = min(p.start_ns for p in self.parts)
        self.end_ns = max(p.end_ns for p in self.parts)
        self._deser_by_part = {id(p): p.deserializer() for p in self.parts}

    def raw(self, topics: set[str] | None) -> Iterator[RawRecord]:
        return heapq.merge(*(p.raw(topics) for p in self.parts), key=lambda r: r.log_time_ns)

    def deserializer(self) -> Callable[[RawRecord], Any]:
        # All parts come from one recording, so their type definitions agree.
        return self.parts[0].deserializer()

    def close(self) -> None:
        for part in self.parts:
            part.close()


class _RecoveredMcapSource:
    """Messages of a truncated MCAP, up to the cut (see :mod:`mcap_recovery`)."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.state = RecoveredStream()
        counts: dict[int, int] = {}
        times: list[int] = []
        for message in iter_recovered(path, self.state):
            counts[message.channel_id] = counts.get(message.channel_id, 0) + 1
            times.append(message.log_time)
        self.message_count = sum(counts.values())
        self.topics: dict[str, TopicInfo] = {}
        for channel_id, count in counts.items():
            channel = self.state.channels.get(channel_id)
            if channel is None:
                continue
            schema = self.state.schemas.get(channel.schema_id)
            msgtype = schema.name if schema else "unknown"
            prev = self.topics.get(channel.topic)
            self.topics[channel.topic] = TopicInfo(channel.topic, msgtype, count + (prev.count if prev else 0))
        self.start_ns = min(times) if times else 0
        self.end_ns = max(times) if times else 0
        self.typestore = _typestore_from_schemas(self.state)

    def raw(self, topics: set[str] | None) -> Iterator[RawRecord]:
        pending: list[tuple[int, int, RawRecord]] = []
        state = RecoveredStream()
        # MCAP files are mostly but not strictly in log-time order; a small heap
        # restores order across chunk boundaries without holding the file.
        horizon_ns = 2_000_000_000
        seq = 0
        for message in iter_recovered(self.path, state):
            channel = state.channels.get(message.channel_id)
            if channel is None or (topics is not None and channel.topic not in topics):
                continue
            schema = state.schemas.get(channel.schema_id)
            rec = RawRecord(channel.topic, schema.name if schema else "unknown", message.log_time, message.data)
            heapq.heappush(pending, (message.log_time, seq, rec))
            seq += 1
            while pending and pending[0][0] < message.log_time - horizon_ns:
                yield heapq.heappop(pending)[2]
        while pending:
            yield heapq.heappop(pending)[2]

    def deserializer(self) -> Callable[[RawRecord], Any]:
        return lambda rec: self.typestore.deserialize_cdr(bytes(rec.raw), rec.msgtype)

    def close(self) -> None:
        pass


def _typestore_from_schemas(state: RecoveredStream) -> Any:
    """A typestore with the recovered MCAP schemas (ROS 2 Humble types as fallback)."""
    typestore = get_typestore(Stores.ROS2_HUMBLE)
    types: dict[str, Any] = {}
    for schema in state.schemas.values():
        text = schema.data.decode("utf-8", "replace")
        if schema.encoding == "ros2msg":
            types.update(get_types_from_msg(text, schema.name))
        elif schema.encoding == "ros2idl":
            sep = "=" * 80 + "\n"
            parts = text.split(sep)[1:] if text.startswith(f"{sep}IDL: ") else [f"IDL: x\n{text}"]
            for part in parts:
                types.update(get_types_from_idl(part.split("\n", 1)[1]))
    typestore.register(types)
    return typestore


def _topics_of(connections: Iterable[Connection], count: Callable[[Connection], int]) -> dict[str, TopicInfo]:
    topics: dict[str, TopicInfo] = {}
    for conn in connections:
        prev = topics.get(conn.topic)
        topics[conn.topic] = TopicInfo(conn.topic, conn.msgtype, count(conn) + (prev.count if prev else 0))
    return topics


def _storage_files(directory: Path) -> list[Path]:
    return sorted(p for p in directory.iterdir() if p.is_file() and p.suffix in (".mcap", ".db3"))


class BagReader:
    """A bag opened for reading; use :func:`open_bag`.

    Attributes:
        path: what the user named.
        kind: 'rosbag2' (directory), 'mcap', 'sqlite3' or 'ros1'.
        topics: topic name -> :class:`TopicInfo`.
        start_ns, end_ns: first and last bag (log) time, int nanoseconds.
        warnings: things the user should know (e.g. a truncated file was recovered).
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.warnings: list[str] = []
        self.kind, self._source = self._open_source()
        self.topics: dict[str, TopicInfo] = dict(sorted(self._source.topics.items()))
        self.start_ns: int = int(self._source.start_ns)
        self.end_ns: int = int(self._source.end_ns)
        self._deserialize = self._source.deserializer()
        if self.message_count == 0:
            self._source.close()
            raise BagError("bag is empty: it holds no messages", self.path)

    # -- opening -----------------------------------------------------------------

    def _open_source(self) -> tuple[str, Any]:
        path = self.path
        if not path.exists():
            raise BagError("no such file or directory", path)
        if path.is_dir():
            return "rosbag2", self._open_directory(path)
        if path.name == "metadata.yaml":
            return "rosbag2", self._open_directory(path.parent)
        if path.stat().st_size == 0:
            raise BagError("file is empty, not a bag", path)
        kind = sniff_kind(path)
        if kind is None:
            raise BagError("not a ROS bag (expected MCAP, rosbag2 sqlite3 or ROS 1 bag data)", path)
        if path.suffix != _SUFFIX_BY_KIND[kind]:
            raise BagError(f"file holds {kind} data but is named '{path.suffix}'; rename it to '{_SUFFIX_BY_KIND[kind]}'", path)
        return kind, self._open_file(path, kind)

    def _open_file(self, path: Path, kind: str) -> Any:
        try:
            return _AnySource([path])
        except _ROSBAGS_ERRORS as err:
            if kind == "mcap":
                return self._recover_mcap(path, err)
            raise BagError(f"cannot read {kind} bag: {err}", path) from err

    def _recover_mcap(self, path: Path, err: Exception) -> _RecoveredMcapSource:
        source = _RecoveredMcapSource(path)
        if source.state.complete and source.message_count == 0:
            raise BagError(f"cannot read MCAP: {err}", path) from err
        if source.message_count == 0:
            raise BagError(f"truncated MCAP (cut at byte {source.state.cut_at_byte}): no message could be recovered", path) from err
        if not source.state.complete:
            self.warnings.append(
                f"{path}: truncated MCAP (no footer; cut at byte {source.state.cut_at_byte}): "
                f"recovered {source.message_count} messages before the cut"
            )
        return source

    def _open_directory(self, directory: Path) -> Any:
        storage = _storage_files(directory)
        if not (directory / "metadata.yaml").exists():
            if not storage:
                raise BagError("directory is not a rosbag2 bag (no metadata.yaml and no .mcap or .db3 file)", directory)
            self.warnings.append(f"{directory}: no metadata.yaml; reading its storage files directly")
            return self._open_storage(storage)
        try:
            source: Any = _AnySource([directory])
        except _ROSBAGS_ERRORS as err:
            if not storage:
                raise BagError(f"cannot read rosbag2 directory: {err}", directory) from err
            self.warnings.append(f"{directory}: rosbag2 metadata unreadable ({err}); reading its storage files directly")
            return self._open_storage(storage)
        promised = sum(t.count for t in source.topics.values())
        if promised > 0 and next(source.raw(None), None) is None and storage:
            source.close()
            self.warnings.append(
                f"{directory}: metadata.yaml promises {promised} messages but the reader yields none "
                "(metadata and storage disagree, e.g. on QoS); reading its storage files directly"
            )
            return self._open_storage(storage)
        return source

    def _open_storage(self, storage: list[Path]) -> Any:
        if len(storage) == 1:
            kind = sniff_kind(storage[0]) or "unknown"
            return self._open_file(storage[0], kind)
        try:
            return _MergedSource(storage)
        except _ROSBAGS_ERRORS as err:
            raise BagError(f"cannot read storage files: {err}", storage[0].parent) from err

    # -- reading -----------------------------------------------------------------

    @property
    def message_count(self) -> int:
        """Number of messages in the bag (recovered ones, for a truncated MCAP)."""
        return sum(t.count for t in self.topics.values())

    @property
    def duration_ns(self) -> int:
        """Time from the first to the last message, int nanoseconds."""
        return max(0, self.end_ns - self.start_ns)

    def require_topic(self, name: str, msgtypes: Iterable[str] | None = None) -> TopicInfo:
        """Return the topic's info, or raise :class:`TopicError` naming what exists."""
        info = self.topics.get(name)
        if info is None:
            known = ", ".join(self.topics) or "none"
            raise TopicError(f"no topic '{name}' in the bag (topics: {known})", self.path)
        allowed = list(msgtypes or [])
        if allowed and info.msgtype not in allowed:
            raise TopicError(f"topic '{name}' has type {info.msgtype}, expected {' or '.join(allowed)}", self.path)
        return info

    def raw_messages(self, topics: Iterable[str] | None = None) -> Iterator[RawRecord]:
        """Yield serialized messages of ``topics`` (all if None) in bag-time order."""
        wanted = None if topics is None else set(topics)
        try:
            yield from self._source.raw(wanted)
        except _ROSBAGS_ERRORS as err:
            raise BagError(f"read error: {err}", self.path) from err

    def deserialize(self, rec: RawRecord) -> Record:
        """Deserialize one raw record into a :class:`Record` (raises :class:`BagError`)."""
        try:
            msg = self._deserialize(rec)
        except _ROSBAGS_ERRORS as err:
            raise BagError(f"cannot decode a {rec.msgtype} message on {rec.topic}: {err}", self.path) from err
        return Record(rec.topic, rec.msgtype, rec.log_time_ns, msg)

    def messages(self, topics: Iterable[str] | None = None) -> Iterator[Record]:
        """Yield deserialized messages of ``topics`` (all if None) in bag-time order."""
        for rec in self.raw_messages(topics):
            yield self.deserialize(rec)

    def close(self) -> None:
        """Release the files."""
        self._source.close()

    def __enter__(self) -> BagReader:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def open_bag(path: str | Path) -> BagReader:
    """Open any bag for reading (see the module docstring); raises :class:`BagError`."""
    return BagReader(path)
