"""Recover the messages of a truncated MCAP file (a robot lost power mid-write).

rosbags needs an MCAP's footer and summary; a file cut short has neither. This
module walks the records from the start with the ``mcap`` package's stream
reader, and when it meets the cut inside a chunk it decompresses that chunk's
prefix as far as the bytes go (zstd and lz4 frames decompress incrementally), so
every message written before the cut is yielded.
"""

from __future__ import annotations

import io
import struct
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

from mcap.exceptions import McapError
from mcap.records import Channel, Chunk, Message, Schema
from mcap.stream_reader import StreamReader

_CHUNK_OPCODE = 0x06
_RECORD_PREFIX = struct.Struct("<BQ")  # opcode, record length
_CHUNK_FIXED = struct.Struct("<QQQI")  # start time, end time, uncompressed size, crc


@dataclass
class RecoveredStream:
    """What a pass over a (possibly truncated) MCAP found.

    ``schemas`` and ``channels`` are keyed by their MCAP ids; ``complete`` is
    false when the file ended before its footer.
    """

    schemas: dict[int, Schema] = field(default_factory=dict)
    channels: dict[int, Channel] = field(default_factory=dict)
    complete: bool = False
    cut_at_byte: int | None = None


def _decompress_prefix(compression: str, data: bytes) -> bytes:
    """Decompress as much of a cut-short chunk body as its bytes allow."""
    if compression == "":
        return data
    if compression == "zstd":
        import zstandard

        return zstandard.ZstdDecompressor().decompressobj().decompress(data)
    if compression == "lz4":
        import lz4.frame

        return lz4.frame.LZ4FrameDecompressor().decompress(data)
    return b""


def _records_of(buffer: bytes) -> Iterator[object]:
    """Yield the complete MCAP records in ``buffer`` (no magic), stopping at a cut."""
    reader = StreamReader(io.BytesIO(buffer), skip_magic=True, record_size_limit=None)
    try:
        yield from reader.records
    except (McapError, struct.error, EOFError, ValueError):
        return


def _partial_chunk(f: io.BufferedReader, start: int) -> tuple[str, bytes] | None:
    """Read the header of the chunk record at ``start``; return (compression, body prefix)."""
    f.seek(start)
    head = f.read(_RECORD_PREFIX.size + _CHUNK_FIXED.size + 4)
    if len(head) < _RECORD_PREFIX.size + _CHUNK_FIXED.size + 4:
        return None
    opcode, _length = _RECORD_PREFIX.unpack_from(head)
    if opcode != _CHUNK_OPCODE:
        return None
    (name_len,) = struct.unpack_from("<I", head, _RECORD_PREFIX.size + _CHUNK_FIXED.size)
    compression = f.read(name_len).decode("utf-8", "replace")
    size_bytes = f.read(8)
    if len(size_bytes) < 8:
        return None
    return compression, f.read()


def iter_recovered(path: Path, state: RecoveredStream) -> Iterator[Message]:
    """Yield the messages of the MCAP at ``path`` in file order, up to any cut.

    Schemas and channels met on the way are stored in ``state`` (before the
    messages that use them are yielded); ``state.complete`` and
    ``state.cut_at_byte`` are set when the pass ends.
    """
    with path.open("rb") as f:
        reader = StreamReader(f, skip_magic=False, emit_chunks=True, record_size_limit=None)
        records = reader.records
        last_good = f.tell()
        while True:
            try:
                record = next(records)
            except StopIteration:
                state.complete = True
                return
            except (McapError, struct.error, EOFError, ValueError):
                break
            position = f.tell()
            if isinstance(record, Chunk):
                inner = _decompress_prefix(record.compression, record.data)
                yield from _take(_records_of(inner), state)
            else:
                yield from _take(iter((record,)), state)
            last_good = position
        # The file ends inside the record that starts at last_good.
        state.cut_at_byte = last_good
        partial = _partial_chunk(f, last_good)
        if partial is not None:
            compression, body = partial
            yield from _take(_records_of(_decompress_prefix(compression, body)), state)


def _take(records: Iterator[object], state: RecoveredStream) -> Iterator[Message]:
    for record in records:
        if isinstance(record, Message):
            yield record
        elif isinstance(record, Schema):
            state.schemas[record.id] = record
        elif isinstance(record, Channel):
            state.channels[record.id] = record
