"""Read an MCAP file that may be damaged: truncated, bad chunks, a broken summary.

A robot that loses power leaves an MCAP without footer or summary; a bad disk or
a bad copy flips bits inside a chunk, or in the summary's offsets. rosbags'
reader needs every part intact and stops at the first bad byte. This module
reads what is readable and says what was lost.

:func:`scan_mcap` walks the file's records once from the start (with the
``mcap`` package's stream reader), decompresses every chunk, checks its CRC and
its declared sizes, and parses the records inside it. A record it cannot read is
skipped: the walk resumes at the next chunk the summary knows of (when the
summary is readable) or ends there, as at a truncation; a chunk cut by a
truncation is decompressed as far as its complete zstd/lz4 blocks go. The scan
keeps the schemas and channels, message counts per channel, the readable
*segments* (chunks, or runs of unchunked messages) in file order, and one-line
descriptions of the damage.

A complete file whose summary agrees with its data is not walked: its schemas,
channels, statistics and chunk indexes come from the summary, each chunk's head
and message indexes are read (not its data) and checked against them, and the
chunks are decompressed and checked only when their messages are read
(``verified`` is then False, and :func:`~bagtools.io.mcap_messages.iter_segments` says the damage it meets).
Commands read a topic or two of a bag: decompressing every chunk of every
topic at open time cost more than reading the scans themselves.
``scan_mcap(path, verify=True)`` always walks and checks everything.

:func:`~bagtools.io.mcap_messages.iter_segments` then streams the messages of the readable segments in
log-time order, exactly: each segment's earliest stamp is known from the scan,
so a message is released once no later segment can hold an earlier one.
"""

from __future__ import annotations

import io
import struct
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from mcap.exceptions import McapError
from mcap.opcode import Opcode
from mcap.records import (Channel, Chunk, ChunkIndex, DataEnd, Footer, Header, Message, MessageIndex, Metadata,
                          MetadataIndex, Schema, Statistics)
from mcap.stream_reader import StreamReader

from bagtools.io.mcap_chunk import (MAX_CHUNK_BYTES, READ_ERRORS, ChunkDamaged, ChunkMessage, chunk_records,
                                    decompress_chunk)

MCAP_MAGIC = b"\x89MCAP0\r\n"
_FOOTER_BYTES = 1 + 8 + 8 + 8 + 4  # opcode, length, summary start, summary offset start, crc


@dataclass
class Segment:
    """Readable messages at one place in the file.

    ``offset`` is the file offset of a chunk record (``n_top_level == 0``) or of
    the first of ``n_top_level`` unchunked message records. ``n_good`` is how
    many messages of it parse (a chunk damaged inside keeps its first ones);
    ``start_ns`` is its earliest log time; ``channels`` the channel ids in it.
    """

    offset: int
    start_ns: int
    n_good: int
    channels: set[int]
    n_top_level: int = 0
    partial_body: bool = False  # a chunk cut short by a truncation: read its prefix


@dataclass
class McapScan:
    """What one pass over an MCAP file found (see the module docstring)."""

    schemas: dict[int, Schema] = field(default_factory=dict)
    channels: dict[int, Channel] = field(default_factory=dict)
    counts: dict[int, int] = field(default_factory=dict)
    segments: list[Segment] = field(default_factory=list)
    start_ns: int | None = None
    end_ns: int | None = None
    complete: bool = False  # the footer was reached
    cut_at_byte: int | None = None  # where a truncated file ends in the middle of a record
    damage: list[str] = field(default_factory=list)
    lost_messages: int = 0
    profile: str | None = None  # the header's profile ('ros2', 'ros1', ...) and writing library
    library: str | None = None
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)  # metadata records by name
    chunk_heads: dict[int, tuple[int, int, int, int]] = field(default_factory=dict)  # offset -> sizes and times
    verified: bool = True  # every chunk was decompressed and checked (False: read from the summary, checked on reading)

    @property
    def message_count(self) -> int:
        return sum(self.counts.values())


def _summary_records(f: io.BufferedReader, size: int) -> list[object] | None:
    """The records of the summary section (from the footer's summary start), None when unreadable or absent."""
    if size < len(MCAP_MAGIC) * 2 + _FOOTER_BYTES:
        return None
    try:
        f.seek(size - len(MCAP_MAGIC) - _FOOTER_BYTES)
        footer = next(StreamReader(f, skip_magic=True, record_size_limit=64).records)
        if not isinstance(footer, Footer) or not 0 < footer.summary_start < size:
            return None
        f.seek(footer.summary_start)
        records = []
        for record in StreamReader(f, skip_magic=True, emit_chunks=True, record_size_limit=size).records:
            if isinstance(record, Footer):
                break
            records.append(record)
        return records
    except (*READ_ERRORS, StopIteration):
        return None


def _footer_summary_start(f: io.BufferedReader, size: int) -> int:
    """The footer's summary start offset (0: no summary, or no readable footer)."""
    try:
        f.seek(size - len(MCAP_MAGIC) - _FOOTER_BYTES)
        footer = next(StreamReader(f, skip_magic=True, record_size_limit=64).records)
        return int(footer.summary_start) if isinstance(footer, Footer) else 0
    except (*READ_ERRORS, StopIteration):
        return 0


def _summary_chunk_offsets(f: io.BufferedReader, size: int) -> list[int]:
    """Chunk offsets from the summary's chunk indexes, or [] when the footer or summary is unreadable."""
    records = _summary_records(f, size) or []
    return sorted(int(r.chunk_start_offset) for r in records
                  if isinstance(r, ChunkIndex) and 0 < r.chunk_start_offset < size)


def _check_summary(f: io.BufferedReader, size: int, scan: McapScan) -> None:
    """Note (as damage) a summary that disagrees with the data: other readers trust it and would fail or lie."""
    records = _summary_records(f, size)
    if records is None:
        if _footer_summary_start(f, size):  # the footer promises a summary that cannot be read
            scan.damage.append("the summary section the footer points to cannot be read (other readers may fail "
                               "on this file); the data itself was read without it")
        return
    wrong = 0
    for record in records:
        if isinstance(record, ChunkIndex):
            head = scan.chunk_heads.get(int(record.chunk_start_offset))
            if head is None or head != (record.compressed_size, record.uncompressed_size, record.message_start_time,
                                        record.message_end_time):
                wrong += 1
        elif isinstance(record, Schema):
            ours = scan.schemas.get(record.id)
            wrong += ours is not None and (ours.name, ours.encoding, bytes(ours.data)) != (
                record.name, record.encoding, bytes(record.data))
        elif isinstance(record, Channel):
            ours = scan.channels.get(record.id)
            wrong += ours is not None and (ours.topic, ours.schema_id, ours.message_encoding) != (
                record.topic, record.schema_id, record.message_encoding)
    if wrong:
        scan.damage.append(f"{wrong} record(s) of the summary section disagree with the data (other readers may fail "
                           "or misread this file); the data itself was read without them")


class _Walker:
    """The top-level records of the file, from ``offset``, as (start offset, record); stops at a bad record."""

    def __init__(self, f: io.BufferedReader, size: int) -> None:
        self.f = f
        self.size = size
        self.error: Exception | None = None
        self.failed_at: int | None = None

    def records(self, offset: int) -> Iterator[tuple[int, object]]:
        self.f.seek(offset)
        reader = StreamReader(self.f, skip_magic=True, emit_chunks=True, record_size_limit=self.size - offset)
        records = reader.records
        position = offset
        while True:
            try:
                record = next(records)
            except StopIteration:
                return
            except READ_ERRORS as err:
                self.error, self.failed_at = err, position
                return
            yield position, record
            position = self.f.tell()


def scan_mcap(path: Path, verify: bool = True) -> McapScan:
    """What is readable in the MCAP at ``path``, and what is damaged (see the module docstring).

    With ``verify`` every record is walked and every chunk decompressed and checked.
    Without, a complete file whose summary agrees with its chunk heads and message
    indexes is described from them (``verified`` False); any other file is walked.
    """
    scan = McapScan()
    with path.open("rb") as f:
        size = f.seek(0, io.SEEK_END)
        f.seek(0)
        if f.read(len(MCAP_MAGIC)) != MCAP_MAGIC:
            scan.damage.append("no MCAP magic at the start")
            return scan
        if not verify and (described := _scan_from_summary(f, size)) is not None:
            return described
        f.seek(len(MCAP_MAGIC))
        walker = _Walker(f, size)
        resync: list[int] | None = None
        offset = len(MCAP_MAGIC)
        run: Segment | None = None  # the current run of unchunked messages
        chunk_tally = [0, 0]  # messages read from the last chunk, and indexed for it by the message indexes after it
        while True:
            for position, record in walker.records(offset):
                if isinstance(record, Chunk):
                    run = None
                    _settle(scan, chunk_tally)
                    chunk_tally = [_scan_chunk(scan, position, record), 0]
                elif isinstance(record, MessageIndex):
                    chunk_tally[1] += len(record.records)
                elif isinstance(record, Message):
                    if run is None:
                        run = Segment(position, record.log_time, 0, set(), n_top_level=0)
                        scan.segments.append(run)
                    run.n_top_level += 1
                    run.n_good += 1
                    run.start_ns = min(run.start_ns, record.log_time)
                    run.channels.add(record.channel_id)
                    _count(scan, record)
                elif isinstance(record, (Schema, Channel)):
                    _register(scan, record)
                elif isinstance(record, Header):
                    scan.profile, scan.library = record.profile, record.library
                elif isinstance(record, Metadata):
                    scan.metadata[record.name] = dict(record.metadata)
                elif isinstance(record, DataEnd):
                    run = None
                elif isinstance(record, Footer):
                    scan.complete = True
            _settle(scan, chunk_tally)
            chunk_tally = [0, 0]
            if scan.complete or walker.failed_at is None:
                if not scan.complete:
                    scan.cut_at_byte = size
                elif not _ends_with_magic(f, size):
                    scan.damage.append("the file ends without its closing magic (cut after the footer); no message "
                                       "is missing")
                else:
                    _check_summary(f, size, scan)
                return _finish(scan)
            # A record could not be read. Resume at the next chunk the summary knows, if any.
            failed_at = walker.failed_at
            if resync is None:
                resync = _summary_chunk_offsets(f, size)
            later = [o for o in resync if o > failed_at]
            if not later:
                if _ends_with_magic(f, size):  # a complete file with a bad record: damage, not a cut
                    scan.complete = True
                    scan.damage.append(f"record at byte {failed_at} unreadable ({_describe(walker.error)}); "
                                       "the rest of the data was skipped")
                else:
                    scan.cut_at_byte = failed_at
                    _recover_cut_chunk(scan, f, failed_at, size)
                return _finish(scan)
            scan.damage.append(f"bytes {failed_at}-{later[0]} unreadable ({_describe(walker.error)}); "
                               "resumed at the next chunk")
            walker.failed_at = None
            offset = later[0]
            run = None


_CHUNK_HEAD = struct.Struct("<BQQQQI")  # opcode, record length, message start, message end, uncompressed size, crc
_INDEX_HEAD = struct.Struct("<BQHI")  # opcode, record length, channel id, byte length of the (log time, offset) pairs


def _scan_from_summary(f: io.BufferedReader, size: int) -> McapScan | None:
    """The scan of a complete file from its summary, chunk heads and message indexes, without
    decompressing a chunk; None when any of them is missing or disagrees with another."""
    if not _ends_with_magic(f, size):
        return None
    records = _summary_records(f, size)
    if not records:
        return None
    stats = [r for r in records if isinstance(r, Statistics)]
    indexes = sorted((r for r in records if isinstance(r, ChunkIndex)), key=lambda r: r.chunk_start_offset)
    if len(stats) != 1 or not indexes:
        return None
    scan = McapScan(complete=True, verified=False)
    for record in records:
        if isinstance(record, (Schema, Channel)):
            _register(scan, record)
    try:
        f.seek(len(MCAP_MAGIC))
        header = next(StreamReader(f, skip_magic=True, record_size_limit=1 << 16).records)
        if isinstance(header, Header):
            scan.profile, scan.library = header.profile, header.library
        for record in records:
            if isinstance(record, MetadataIndex):
                f.seek(record.offset)
                metadata = next(StreamReader(f, skip_magic=True, record_size_limit=record.length).records)
                if isinstance(metadata, Metadata):
                    scan.metadata[metadata.name] = dict(metadata.metadata)
        for index in indexes:
            segment = _indexed_segment(f, size, scan, index)
            if segment is None:
                return None
            scan.segments.append(segment)
    except (*READ_ERRORS, StopIteration):
        return None
    statistics = stats[0]
    if scan.message_count != statistics.message_count or any(
            scan.counts.get(cid, 0) != n for cid, n in statistics.channel_message_counts.items()):
        return None  # messages outside the chunks, or statistics that disagree: walk the file
    return _finish(scan)


def _indexed_segment(f: io.BufferedReader, size: int, scan: McapScan, index: ChunkIndex) -> Segment | None:
    """The segment of the chunk ``index`` points to, from its head and message indexes (counted into
    ``scan``), or None when they disagree with the index or name an undeclared channel."""
    offset, end = int(index.chunk_start_offset), int(index.chunk_start_offset) + int(index.chunk_length)
    if not 0 < offset < end <= size - int(index.message_index_length):
        return None
    f.seek(offset)
    head = f.read(_CHUNK_HEAD.size)
    if len(head) < _CHUNK_HEAD.size:
        return None
    opcode, length, start_ns, end_ns, uncompressed, _ = _CHUNK_HEAD.unpack(head)
    if (opcode != Opcode.CHUNK or 1 + 8 + length != index.chunk_length or uncompressed != index.uncompressed_size
            or (start_ns, end_ns) != (index.message_start_time, index.message_end_time)):
        return None
    f.seek(end)
    data = f.read(int(index.message_index_length))
    segment = Segment(offset, start_ns, 0, set())
    pos = 0
    while pos < len(data):
        if len(data) - pos < _INDEX_HEAD.size:
            return None
        opcode, length, channel_id, pairs_bytes = _INDEX_HEAD.unpack_from(data, pos)
        if opcode != Opcode.MESSAGE_INDEX or pairs_bytes % 16 or 2 + 4 + pairs_bytes != length \
                or channel_id not in scan.channels:
            return None
        n = pairs_bytes // 16
        if n:
            stamps = np.frombuffer(data, dtype="<u8", count=2 * n, offset=pos + _INDEX_HEAD.size)[::2]
            low, high = int(stamps.min()), int(stamps.max())
            if not start_ns <= low <= high <= end_ns:
                return None
            scan.counts[channel_id] = scan.counts.get(channel_id, 0) + n
            scan.start_ns = low if scan.start_ns is None else min(scan.start_ns, low)
            scan.end_ns = high if scan.end_ns is None else max(scan.end_ns, high)
            segment.n_good += n
            segment.channels.add(channel_id)
        pos += 1 + 8 + length
    if pos != len(data) or not segment.channels <= set(index.message_index_offsets):
        return None
    return segment


def _ends_with_magic(f: io.BufferedReader, size: int) -> bool:
    f.seek(max(0, size - len(MCAP_MAGIC)))
    return f.read(len(MCAP_MAGIC)) == MCAP_MAGIC


def _settle(scan: McapScan, chunk_tally: list[int]) -> None:
    """Count the messages a chunk's indexes promise beyond those it gave."""
    scan.lost_messages += max(0, chunk_tally[1] - chunk_tally[0])


def _scan_chunk(scan: McapScan, position: int, chunk: Chunk, partial: bool = False) -> int:
    """Add a chunk's readable messages to ``scan`` (noting any damage); return how many there are."""
    if not partial:
        scan.chunk_heads[position] = (len(chunk.data), chunk.uncompressed_size, chunk.message_start_time,
                                      chunk.message_end_time)
    try:
        data = decompress_chunk(chunk, allow_partial=partial)
    except ChunkDamaged as err:
        scan.damage.append(f"chunk at byte {position} {err}; its messages are skipped")
        return 0
    segment = Segment(position, chunk.message_start_time, 0, set(), partial_body=partial)
    try:
        for record in checked_records(scan, chunk, data):
            if isinstance(record, ChunkMessage):
                segment.n_good += 1
                segment.channels.add(record.channel_id)
                segment.start_ns = min(segment.start_ns, record.log_time)
                _count(scan, record)
    except READ_ERRORS as err:
        if not partial:
            scan.damage.append(damaged_after(position, segment.n_good, err))
    if segment.n_good:
        scan.segments.append(segment)
    return segment.n_good


def damaged_after(position: int, n_good: int, err: BaseException) -> str:
    return (f"chunk at byte {position} is damaged after {n_good} messages ({_describe(err)}); "
            "the rest of it is skipped")


def _recover_cut_chunk(scan: McapScan, f: io.BufferedReader, position: int, size: int) -> None:
    """The file ends inside the record at ``position``: if it is a chunk, take what its prefix holds."""
    chunk = read_cut_chunk(f, position, size)
    if chunk is not None:
        _scan_chunk(scan, position, chunk, partial=True)


def read_cut_chunk(f: io.BufferedReader, position: int, size: int) -> Chunk | None:
    """The chunk record at ``position`` with as much of its data as the file holds (None if not a chunk)."""
    head_size = 1 + 8 + 8 + 8 + 8 + 4 + 4
    f.seek(position)
    head = f.read(head_size)
    if len(head) < head_size or head[0] != 0x06:
        return None
    start_ns, end_ns, uncompressed_size, crc, name_len = struct.unpack_from("<QQQII", head, 9)
    if name_len > 64:
        return None
    compression = f.read(name_len).decode("utf-8", "replace")
    if len(f.read(8)) < 8:
        return None
    data = f.read(max(0, min(size - f.tell(), MAX_CHUNK_BYTES)))
    return Chunk(compression=compression, data=data, message_end_time=end_ns, message_start_time=start_ns,
                 uncompressed_crc=crc, uncompressed_size=min(uncompressed_size, MAX_CHUNK_BYTES))


def _describe(err: BaseException) -> str:
    text = " ".join(str(err).split())[:120]
    return text if isinstance(err, McapError) and text else f"{type(err).__name__}: {text}".rstrip(": ")


def _count(scan: McapScan, message: Message) -> None:
    scan.counts[message.channel_id] = scan.counts.get(message.channel_id, 0) + 1
    t = message.log_time
    scan.start_ns = t if scan.start_ns is None else min(scan.start_ns, t)
    scan.end_ns = t if scan.end_ns is None else max(scan.end_ns, t)


def _register(scan: McapScan, record: Schema | Channel) -> None:
    if isinstance(record, Schema):
        scan.schemas.setdefault(record.id, record)
    else:
        scan.channels.setdefault(record.id, record)


def _finish(scan: McapScan) -> McapScan:
    scan.segments.sort(key=lambda s: s.offset)
    return scan


def checked_records(scan: McapScan, chunk: Chunk, data: bytes, wanted: set[int] | None = None,
                     tally: list[int] | None = None) -> Iterator[Schema | Channel | ChunkMessage]:
    """The records of a decompressed chunk (messages on ``wanted`` channels only, all if None; every message
    counted in ``tally``); the schemas and channels in it are registered in ``scan``.

    Without a CRC, damage shows as records that contradict the chunk: a message on
    a channel never declared, or stamped outside the chunk's declared time range.
    Raises an MCAP error there (what came before has been yielded).
    """
    def check(channel_id: int, log_time: int) -> None:
        if channel_id not in scan.channels:
            raise McapError(f"a message on undeclared channel {channel_id}")
        if not chunk.message_start_time <= log_time <= chunk.message_end_time:
            raise McapError("a message stamped outside the chunk's time range")

    for record in chunk_records(data, wanted, check, tally):
        if isinstance(record, (Schema, Channel)):
            _register(scan, record)
        yield record
