"""One reader facade over every bag format a user may have.

``open_bag(path)`` accepts a rosbag2 directory (MCAP or sqlite3 storage, with or
without metadata.yaml), a bare ``.mcap`` or ``.db3`` file, or a ROS 1 ``.bag``,
and yields time-ordered records. Formats are told apart by their magic bytes,
not by trust in the suffix. Damage is read around, and said in :attr:`BagReader.warnings`:

- MCAP files (bare, or the storage of a rosbag2 directory) are read by
  :mod:`bagtools.io.mcap_source`: a truncated file up to the cut, a damaged chunk
  or summary skipped, a garbled message definition costing only its topic. A
  complete file whose summary agrees with its data opens from the summary, and
  its chunks are checked as they are read: their damage is said then;
- ROS 1 and sqlite3 bags are read with rosbags; a damaged chunk of a ROS 1 bag is skipped (its index, at the
  end of the file, finds the chunks after it) and said; any other read error in the middle ends
  the stream with a warning, and a message that cannot be decoded is skipped and
  counted;
- a rosbag2 directory whose metadata.yaml counts no messages, or promises
  messages that rosbags then does not yield (seen with rosbags 0.11.9 when the
  metadata's QoS differs from the storage file's), is re-read from its storage
  files directly.
"""

from __future__ import annotations

import heapq
import importlib
import struct
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

from rosbags.highlevel import AnyReader, AnyReaderError
from rosbags.rosbag1 import ReaderError as Rosbag1ReaderError
from rosbags.rosbag2 import ReaderError as Rosbag2ReaderError
from rosbags.serde import SerdeError
from rosbags.interfaces import Connection
from rosbags.typesys import Stores, TypesysError, get_types_from_idl, get_types_from_msg, get_typestore

from bagtools.errors import BagError, BagtoolsError, TopicError
from bagtools.io.mcap_source import MCAP_MAGIC, McapScan, iter_segments, scan_mcap



def _apsw_errors() -> tuple[type[Exception], ...]:
    try:
        import apsw
    except ImportError:  # rosbags reads sqlite3 through apsw; without it there is nothing to catch
        return ()
    return (apsw.Error,)


def _zstd_errors() -> tuple[type[Exception], ...]:
    """The zstd libraries' errors (damaged compressed data): rosbags decompresses a rosbag2 file (or message)
    compressed with zstd through ``backports.zstd`` or ``compression.zstd``, the mcap library through ``zstandard``."""
    errors: list[type[Exception]] = []
    for module in ("compression.zstd", "backports.zstd", "zstandard"):
        try:
            errors.append(importlib.import_module(module).ZstdError)
        except (ImportError, AttributeError):
            continue
    return tuple(errors)


def _one_line(err: BaseException) -> str:
    """An exception as a short single line: its type and its first 200 characters."""
    text = " ".join(str(err).split())
    return f"{type(err).__name__}: {text[:200]}" if text else type(err).__name__


ROS1_MAGIC = b"#ROSBAG V2.0"
SQLITE_MAGIC = b"SQLite format 3\x00"
_KIND_BY_MAGIC = {MCAP_MAGIC: "mcap", ROS1_MAGIC: "ros1", SQLITE_MAGIC: "sqlite3"}
_SUFFIX_BY_KIND = {"mcap": ".mcap", "ros1": ".bag", "sqlite3": ".db3"}
# What rosbags (and apsw, numpy, zstd underneath) raise on damaged files and messages.
_READ_ERRORS = (AnyReaderError, Rosbag1ReaderError, Rosbag2ReaderError, TypesysError, SerdeError, OSError, KeyError,
                ValueError,
                TypeError, AssertionError, IndexError, AttributeError, OverflowError, MemoryError, EOFError,
                struct.error, *_apsw_errors(), *_zstd_errors())


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
    publisher: str = ""  # the node that published it, where the bag says (a ROS 1 connection's callerid)


@dataclass(frozen=True, slots=True)
class Record:
    """One deserialized message (a rosbags message object) with its bag time in ns."""

    topic: str
    msgtype: str
    log_time_ns: int
    msg: Any
    publisher: str = ""


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

    #: How read_damage is said (MCAP's source says "damaged MCAP").
    damage_kind = "damaged ROS 1 bag"

    def __init__(self, paths: list[Path]) -> None:
        self.path = paths[0]
        self.reader = AnyReader(paths, default_typestore=get_typestore(Stores.ROS2_HUMBLE))
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


class _MergedSource:
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


class _McapSource:
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


def _metadata_disagreements(directory: Path, storage: list[Path], source: Any) -> list[str]:
    """What a rosbag2 metadata.yaml gets wrong about the MCAP files beside it (read directly instead)."""
    from ruamel.yaml import YAML, YAMLError

    where = directory / "metadata.yaml"
    try:
        info = YAML(typ="safe", pure=True).load(where.read_bytes())["rosbag2_bagfile_information"]
        topics = [t["topic_metadata"] for t in info.get("topics_with_message_count") or []]
        counts = {t["topic_metadata"]["name"]: int(t["message_count"]) for t in info.get("topics_with_message_count") or []}
        types = {str(t["name"]): str(t.get("type", "")) for t in topics}
        files = [str(f) for f in info.get("relative_file_paths") or []]
        compression = (str(info.get("compression_mode") or ""), str(info.get("compression_format") or ""))
        version = int(info.get("version", 0))
        storage_id = str(info.get("storage_identifier", ""))
    except (YAMLError, OSError, UnicodeDecodeError, KeyError, TypeError, ValueError, AttributeError) as err:
        return [f"{where}: unreadable ({_one_line(err)}); read the storage files directly"]
    out = []
    if not 1 <= version <= MAX_METADATA_VERSION:
        out.append(f"{where}: version {version} is not one rosbag2 writes (1..{MAX_METADATA_VERSION}); "
                   "read the storage files directly")
    if storage_id and storage_id != "mcap":
        out.append(f"{where}: says the storage is {storage_id!r}, but the files are MCAP; read them as MCAP")
    wrong_types = [f"{name} ({types[name]} there, {info.msgtype} in the file)" for name, info in source.topics.items()
                   if types.get(name) and types[name] != info.msgtype]
    if wrong_types:
        out.append(f"{where}: topic types disagree with the MCAP schemas: {', '.join(wrong_types[:3])}; "
                   "using the file's")
    missing = [f for f in files if not (directory / f).exists()]
    if missing:
        out.append(f"{where}: lists files that are not there ({', '.join(missing[:3])}); read the storage files directly")
    if compression[0].lower() == "file" and compression[1]:
        out.append(f"{where}: says the files are {compression[1]}-compressed, but they are plain MCAP; read as they are")
    stored = sum(t.count for t in source.topics.values())
    if counts and sum(counts.values()) != stored:
        out.append(f"{where}: counts {sum(counts.values())} messages, the storage holds {stored}; trusting the storage")
    return out


#: The newest rosbag2 metadata version (Rolling/Kilted write 9).
MAX_METADATA_VERSION = 9


def _storage_files(directory: Path) -> list[Path]:
    return sorted(p for p in directory.iterdir() if p.is_file() and p.suffix in (".mcap", ".db3"))


class BagReader:
    """A bag opened for reading; use :func:`open_bag`.

    Attributes:
        path: what the user named.
        kind: 'rosbag2' (directory), 'mcap', 'sqlite3', 'ros1' or 'carmen' (a CARMEN log, :mod:`bagtools.io.carmen`).
        topics: topic name -> :class:`TopicInfo`.
        start_ns, end_ns: first and last bag (log) time, int nanoseconds.
        warnings: things the user should know (e.g. a truncated file was recovered).
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.warnings: list[str] = []
        #: topic -> (messages skipped because they cannot be decoded, the first one's problem)
        self.undecodable: dict[str, tuple[int, str]] = {}
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
            from bagtools.io.carmen import CarmenSource, looks_like_carmen  # it builds on this module's records
            if looks_like_carmen(path):
                source = CarmenSource(path)
                self.warnings.extend(source.warnings)
                return "carmen", source
            raise BagError("not a ROS bag (expected MCAP, rosbag2 sqlite3 or ROS 1 bag data, or a CARMEN log)", path)
        if path.suffix != _SUFFIX_BY_KIND[kind]:
            raise BagError(f"file holds {kind} data but is named '{path.suffix}'; rename it to '{_SUFFIX_BY_KIND[kind]}'", path)
        return kind, self._open_file(path, kind)

    def _open_file(self, path: Path, kind: str) -> Any:
        if kind == "mcap":
            return self._open_mcap(path)
        try:
            return _AnySource([path])
        except _READ_ERRORS as err:
            raise BagError(f"cannot read {kind} bag: {_one_line(err)}", path) from err

    def _open_mcap(self, path: Path) -> _McapSource:
        source = _McapSource(path)
        self.warnings.extend(source.warnings)
        if source.message_count == 0:
            scan = source.scan
            if not scan.complete and scan.cut_at_byte is not None and not scan.damage:
                raise BagError(f"truncated MCAP (cut at byte {scan.cut_at_byte}): no message could be recovered", path)
            if scan.damage:
                raise BagError(f"damaged MCAP, no message could be read: {scan.damage[0]}", path)
            if scan.message_count:
                raise BagError("no message can be decoded: " + "; ".join(w.split(": ", 1)[1] for w in source.warnings),
                               path)
        return source

    def _open_directory(self, directory: Path) -> Any:
        storage = _storage_files(directory)
        if not (directory / "metadata.yaml").exists():
            if not storage:
                raise BagError("directory is not a rosbag2 bag (no metadata.yaml and no .mcap or .db3 file)", directory)
            self.warnings.append(f"{directory}: no metadata.yaml; reading its storage files directly")
            return self._open_storage(storage)
        if storage and all(p.suffix == ".mcap" for p in storage):
            # MCAP files carry their own schemas and counts: read them directly, which also survives
            # damage and a metadata.yaml that disagrees with them (counts, QoS, compression).
            source = self._open_storage(storage)
            self.warnings.extend(_metadata_disagreements(directory, storage, source))
            return source
        try:
            source: Any = _AnySource([directory])
        except _READ_ERRORS as err:
            if not storage:
                raise BagError(f"cannot read rosbag2 directory: {_one_line(err)}", directory) from err
            self.warnings.append(f"{directory}: rosbag2 metadata unreadable ({_one_line(err)}); "
                                 "reading its storage files directly")
            return self._open_storage(storage)
        promised = sum(t.count for t in source.topics.values())
        if storage and promised == 0:
            source.close()
            self.warnings.append(f"{directory}: metadata.yaml counts no messages; reading its storage files directly")
            return self._open_storage(storage)
        if promised > 0 and next(source.raw(None), None) is None and storage:
            source.close()
            self.warnings.append(
                f"{directory}: metadata.yaml promises {promised} messages but the reader yields none "
                "(metadata and storage disagree, e.g. on QoS); reading its storage files directly"
            )
            return self._open_storage(storage)
        return source

    def _open_storage(self, storage: list[Path]) -> Any:
        parts = [self._open_file(p, sniff_kind(p) or "unknown") for p in storage]
        return parts[0] if len(parts) == 1 else _MergedSource(parts)

    # -- reading -----------------------------------------------------------------

    @property
    def message_count(self) -> int:
        """Number of messages in the bag (recovered ones, for a truncated MCAP; for an intact-looking MCAP,
        whose chunks are checked as they are read, the count its indexes give)."""
        return sum(t.count for t in self.topics.values())

    @property
    def duration_ns(self) -> int:
        """Time from the first to the last message, int nanoseconds."""
        return max(0, self.end_ns - self.start_ns)

    def storage_files(self) -> list[Path]:
        """The files that hold the messages (a rosbag2 directory's .mcap/.db3 files, or the bag file itself)."""
        directory = self.path.parent if self.path.name == "metadata.yaml" else self.path
        return _storage_files(directory) if directory.is_dir() else [self.path]

    def storage_sources(self) -> list[Any]:
        """The readers of the storage files (for :func:`bagtools.io.storage.storage_details`)."""
        return list(self._source.parts) if isinstance(self._source, _MergedSource) else [self._source]

    def field_definitions(self, msgtype: str) -> tuple[list, list]:
        """rosbags' definition of ``msgtype`` as the bag declares it: (constants, fields), each field
        ``(name, (Nodetype, detail))``; what a field's ROS type is (uint64, float32[3], ...), which the message
        object's Python values do not say."""
        return self._source.typestore.fielddefs[msgtype]

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
        """Yield serialized messages of ``topics`` (all if None) in bag-time order.

        A read error in the middle of a damaged ROS 1 or sqlite3 bag ends the
        stream with a warning in :attr:`warnings` (what was read is kept);
        damaged MCAP chunks were already skipped when the bag was opened.
        """
        wanted = None if topics is None else set(topics)
        n = 0
        try:
            for rec in self._source.raw(wanted):
                yield rec
                n += 1
        except _READ_ERRORS as err:
            self._warn_once(f"{self.path}: read error after {n} messages ({_one_line(err)}); "
                            "the rest of the bag could not be read")
        finally:
            damage = self._warn_read_damage()
        if n == 0 and damage:
            what = "no message" if wanted is None else f"no message of {', '.join(sorted(wanted))}"
            kind = getattr(self._source, "damage_kind", "damaged MCAP")
            raise BagError(f"{kind}: {what} could be read (all of it lay in damaged chunks; the rest of the bag "
                           f"may be intact): {damage[0]}", self.path)

    def _warn_read_damage(self) -> list[str]:
        """Say the damage met while reading (MCAP chunks first checked then, ROS 1 chunks read past); return it."""
        met = [(source, d) for source in self.storage_sources() for d in getattr(source, "read_damage", ())]
        for source, damage in met:
            self._warn_once(f"{source.path}: {getattr(source, 'damage_kind', 'damaged MCAP')}: {damage}")
        return [damage for _, damage in met]

    def deserialize(self, rec: RawRecord) -> Record:
        """Deserialize one raw record into a :class:`Record` (raises :class:`BagError`)."""
        try:
            msg = self._deserialize(rec)
        except _READ_ERRORS as err:
            raise BagError(f"cannot decode a {rec.msgtype} message on {rec.topic}: {_one_line(err)}", self.path) from err
        return Record(rec.topic, rec.msgtype, rec.log_time_ns, msg, rec.publisher)

    def messages(self, topics: Iterable[str] | None = None,
                 from_cdr: Mapping[str, Callable[[bytes | memoryview], Any]] | None = None) -> Iterator[Record]:
        """Yield deserialized messages of ``topics`` (all if None) in bag-time order.

        A message that cannot be decoded (damaged bytes) is skipped; how many,
        per topic, is added to :attr:`warnings` when the iteration ends.
        ``from_cdr`` maps topics to decoders of their CDR bytes (e.g.
        :func:`bagtools.io.cdr.laserscan_from_cdr` for a LaserScan topic): a
        message of such a topic stored as CDR is decoded straight from its bytes,
        and what the decoder returns is the record's ``msg``; where it returns
        None, the message is deserialized as usual.
        """
        failed: dict[str, int] = {}
        first_by_topic: dict[str, str] = {}
        first_error = ""
        fast = {t: d for t, d in (from_cdr or {}).items() if t in self._source.cdr_topics}
        try:
            for rec in self.raw_messages(topics):
                decode = fast.get(rec.topic)
                if decode is not None and (decoded := decode(rec.raw)) is not None:
                    yield Record(rec.topic, rec.msgtype, rec.log_time_ns, decoded, rec.publisher)
                    continue
                try:
                    yield self.deserialize(rec)
                except BagError as err:
                    failed[rec.topic] = failed.get(rec.topic, 0) + 1
                    first_error = first_error or err.problem
                    first_by_topic.setdefault(rec.topic, err.problem)
        finally:
            for topic, n in failed.items():  # a topic read twice (a first pass for its stamps) counts once
                self.undecodable[topic] = (max(n, self.undecodable.get(topic, (0, ""))[0]), first_by_topic[topic])
            if failed:
                counts = ", ".join(f"{n} on {topic}" for topic, n in failed.items())
                self._warn_once(f"{self.path}: skipped messages that cannot be decoded ({counts}; first: {first_error})")

    def decode_note(self, topic: str) -> str:
        """' (N of its messages cannot be decoded: PROBLEM)' when reading ``topic`` skipped damaged messages, else
        '': for an error that says a topic held nothing usable, so that it says why."""
        if topic not in self.undecodable:
            return ""
        n, problem = self.undecodable[topic]
        return f" ({n} of its messages cannot be decoded, the bag is damaged: {problem})"

    def _warn_once(self, warning: str) -> None:
        if warning not in self.warnings:
            self.warnings.append(warning)

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
