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

from collections.abc import Callable, Iterable, Iterator, Mapping
from pathlib import Path
from typing import Any

from bagtools.errors import BagError, TopicError
from bagtools.io.mcap_source import MCAP_MAGIC
from bagtools.io.records import READ_ERRORS, RawRecord, Record, TopicInfo, one_line
from bagtools.io.sources import AnySource, McapSource, MergedSource

ROS1_MAGIC = b"#ROSBAG V2.0"
SQLITE_MAGIC = b"SQLite format 3\x00"
_KIND_BY_MAGIC = {MCAP_MAGIC: "mcap", ROS1_MAGIC: "ros1", SQLITE_MAGIC: "sqlite3"}
_SUFFIX_BY_KIND = {"mcap": ".mcap", "ros1": ".bag", "sqlite3": ".db3"}
def sniff_kind(path: Path) -> str | None:
    """Return 'mcap', 'ros1' or 'sqlite3' from a file's magic bytes, or None."""
    with path.open("rb") as f:
        head = f.read(16)
    for magic, kind in _KIND_BY_MAGIC.items():
        if head.startswith(magic):
            return kind
    return None


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
        return [f"{where}: unreadable ({one_line(err)}); read the storage files directly"]
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
            return AnySource([path])
        except READ_ERRORS as err:
            raise BagError(f"cannot read {kind} bag: {one_line(err)}", path) from err

    def _open_mcap(self, path: Path) -> McapSource:
        source = McapSource(path)
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
            source: Any = AnySource([directory])
        except READ_ERRORS as err:
            if not storage:
                raise BagError(f"cannot read rosbag2 directory: {one_line(err)}", directory) from err
            self.warnings.append(f"{directory}: rosbag2 metadata unreadable ({one_line(err)}); "
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
        return parts[0] if len(parts) == 1 else MergedSource(parts)

    # -- reading -----------------------------------------------------------------

    @property
    def message_count(self) -> int:
        """Number of messages in the bag (recovered ones, for a truncated MCAP; for an intact-looking MCAP,
        whose chunks are checked as they are read, the count its indexes give)."""
        return sum(t.count for t in self.topics.values())

    @property
    def seq_is_recording_order(self) -> bool:
        """Whether each message's ``header.seq`` is its place in the recording, whatever its stamp says (a
        CARMEN log's line order), not a publisher's counter that may restart or interleave with another's."""
        return bool(getattr(self._source, "seq_is_recording_order", False))

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
        return list(self._source.parts) if isinstance(self._source, MergedSource) else [self._source]

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
        except READ_ERRORS as err:
            self._warn_once(f"{self.path}: read error after {n} messages ({one_line(err)}); "
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
        except READ_ERRORS as err:
            raise BagError(f"cannot decode a {rec.msgtype} message on {rec.topic}: {one_line(err)}", self.path) from err
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
