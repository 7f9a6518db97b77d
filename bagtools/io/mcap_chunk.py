"""The records inside one MCAP chunk: decompressed and checked (:func:`decompress_chunk`), then parsed without the
``mcap`` package's per-record objects (:func:`chunk_records`), messages as light tuples over the decompressed bytes
(:class:`ChunkMessage`). What :mod:`bagtools.io.mcap_source` scans a file with and reads its messages through."""

from __future__ import annotations

import io
import struct
import zlib
from collections.abc import Callable, Iterator
from typing import NamedTuple

from mcap.data_stream import ReadDataStream
from mcap.exceptions import McapError
from mcap.opcode import Opcode
from mcap.records import Channel, Chunk, Schema

#: Largest decompressed chunk accepted (a damaged size field must not make us allocate terabytes).
MAX_CHUNK_BYTES = 1 << 30
#: What reading a damaged MCAP record may raise (the mcap package's own errors and those of the bytes beneath).
READ_ERRORS = (McapError, EOFError, struct.error, ValueError, UnicodeDecodeError, OverflowError, MemoryError, IndexError,
               KeyError, TypeError, AttributeError)


class ChunkDamaged(Exception):
    """A chunk cannot be used: what is wrong, in words."""


def decompress_chunk(chunk: Chunk, allow_partial: bool = False) -> bytes:
    """The records of ``chunk``, decompressed and CRC-checked; raises :class:`ChunkDamaged`.

    With ``allow_partial`` (a chunk cut by a truncation) as much as the data
    gives is returned and neither the size nor the CRC is checked.
    """
    if chunk.uncompressed_size > MAX_CHUNK_BYTES:
        raise ChunkDamaged(f"declares {chunk.uncompressed_size} uncompressed bytes (limit {MAX_CHUNK_BYTES})")
    try:
        if chunk.compression == "":
            data = bytes(chunk.data)
        elif chunk.compression == "zstd":
            import zstandard

            if allow_partial:
                data = zstandard.ZstdDecompressor().decompressobj().decompress(chunk.data)
            else:  # never more than the declared size (+1 to see a lie), whatever the frame header says
                data = zstandard.ZstdDecompressor().stream_reader(chunk.data).read(chunk.uncompressed_size + 1)
        elif chunk.compression == "lz4":
            import lz4.frame

            data = lz4.frame.LZ4FrameDecompressor().decompress(chunk.data)
        else:
            raise ChunkDamaged(f"unknown compression {chunk.compression[:40]!r}")
    except ChunkDamaged:
        raise
    except Exception as err:  # zstd/lz4 raise their own error types on corrupt frames
        raise ChunkDamaged(f"does not decompress ({type(err).__name__}: {err})") from err
    if allow_partial:
        return data
    if len(data) != chunk.uncompressed_size:
        raise ChunkDamaged(f"decompresses to {len(data)} bytes, not the {chunk.uncompressed_size} it declares")
    if chunk.uncompressed_crc != 0 and zlib.crc32(data) != chunk.uncompressed_crc:
        raise ChunkDamaged("checksum mismatch (CRC of its records differs from the one recorded)")
    return data


class ChunkMessage(NamedTuple):
    """A message record read from a chunk: the fields of :class:`mcap.records.Message`, as a light tuple
    (a bag holds them by the hundred thousand); ``data`` is a view of the decompressed chunk."""

    channel_id: int
    sequence: int
    log_time: int
    publish_time: int
    data: memoryview


_RECORD_HEAD = struct.Struct("<BQ")  # opcode, record length
_MESSAGE_HEAD = struct.Struct("<HIQQ")  # channel id, sequence, log time, publish time


def chunk_records(data: bytes, wanted: set[int] | None = None, check: Callable[[int, int], None] | None = None,
                  tally: list[int] | None = None) -> Iterator[Schema | Channel | ChunkMessage]:
    """The schema, channel and message records packed in a decompressed chunk, in order.

    Message payloads are zero-copy views of ``data``. Raises an MCAP error where
    the records stop parsing (a damaged length); what came before has been yielded.
    With ``wanted``, only the messages on those channel ids are yielded (the others
    are parsed and counted, not built: a bag's other topics cost little); every
    message is passed to ``check`` (channel id, log time), which raises on damage,
    and counted in ``tally[0]`` once it passed.
    """
    view = memoryview(data)
    end = len(data)
    pos = 0
    while pos < end:
        if end - pos < _RECORD_HEAD.size:
            raise McapError(f"{end - pos} stray bytes at the end of a chunk")
        opcode, length = _RECORD_HEAD.unpack_from(data, pos)
        body = pos + _RECORD_HEAD.size
        if length > end - body:
            raise McapError(f"record of {length} bytes overruns its chunk")
        if opcode == Opcode.MESSAGE:
            if length < _MESSAGE_HEAD.size:
                raise McapError(f"message record of {length} bytes is too short")
            channel_id, sequence, log_time, publish_time = _MESSAGE_HEAD.unpack_from(data, body)
            if check is not None:
                check(channel_id, log_time)
            if tally is not None:
                tally[0] += 1
            if wanted is None or channel_id in wanted:
                yield ChunkMessage(channel_id, sequence, log_time, publish_time,
                                   view[body + _MESSAGE_HEAD.size: body + length])
        elif opcode in (Opcode.SCHEMA, Opcode.CHANNEL):
            stream = ReadDataStream(io.BytesIO(view[body: body + length]))
            yield Schema.read(stream) if opcode == Opcode.SCHEMA else Channel.read(stream)
        pos = body + length
