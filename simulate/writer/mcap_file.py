"""A streaming MCAP writer (format version 0) for many small messages: chunks built with numpy.

Written from the MCAP specification (mcap.dev/spec): header; a data section of zstd chunks,
each followed by its message indexes; a ``rosbag2`` metadata record; then a summary section of
schemas, channels, statistics, metadata index and chunk indexes, summary offsets and a footer.
Every chunk carries the CRC-32 of its uncompressed records and the footer the CRC-32 of the
summary, as libmcap writes them by default (the data-section CRC is 0: not computed, as in
libmcap). Schemas and channels are written at the start of the first chunk and repeated in the
summary.

``add_message`` only appends to lists; when a chunk's worth of messages is queued, their
record headers, offsets and message indexes are built in one go with numpy, so writing costs
about a microsecond per message.
"""

from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass
from typing import BinaryIO

import numpy as np
import zstandard

MAGIC = b"\x89MCAP0\r\n"
_OP = {"header": 0x01, "footer": 0x02, "schema": 0x03, "channel": 0x04, "message": 0x05, "chunk": 0x06,
       "message_index": 0x07, "chunk_index": 0x08, "statistics": 0x0B, "metadata": 0x0C, "metadata_index": 0x0D,
       "summary_offset": 0x0E, "data_end": 0x0F}
# A Message record's opcode, length and fixed fields: opcode u8, length u64, channel u16, sequence u32,
# log time u64, publish time u64 (then the data).
_MESSAGE_HEAD = np.dtype([("op", "u1"), ("length", "<u8"), ("channel", "<u2"), ("sequence", "<u4"),
                          ("log_time", "<u8"), ("publish_time", "<u8")])
_MESSAGE_FIXED = _MESSAGE_HEAD.itemsize - 9  # bytes of the record body before the data
_INDEX_ENTRY = np.dtype([("log_time", "<u8"), ("offset", "<u8")])


def _string(text: str) -> bytes:
    raw = text.encode("utf-8")
    return struct.pack("<I", len(raw)) + raw


def _map(items: dict[str, str]) -> bytes:
    body = b"".join(_string(k) + _string(v) for k, v in items.items())
    return struct.pack("<I", len(body)) + body


def _record(opcode: int, body: bytes) -> bytes:
    return struct.pack("<BQ", opcode, len(body)) + body


@dataclass(frozen=True)
class _ChunkIndex:
    start_ns: int
    end_ns: int
    offset: int
    length: int
    index_offsets: list[tuple[int, int]]
    index_length: int
    compressed_size: int
    uncompressed_size: int

    def record(self) -> bytes:
        offsets = b"".join(struct.pack("<HQ", cid, off) for cid, off in self.index_offsets)
        body = (struct.pack("<QQQQ", self.start_ns, self.end_ns, self.offset, self.length)
                + struct.pack("<I", len(offsets)) + offsets
                + struct.pack("<Q", self.index_length) + _string("zstd")
                + struct.pack("<QQ", self.compressed_size, self.uncompressed_size))
        return _record(_OP["chunk_index"], body)


class McapFileWriter:
    """Write one MCAP file to the open binary ``stream``; call ``finish`` to complete it.

    Register every schema and channel before the first message; messages must come in
    log-time order (as rosbag2 writes them). Times are int nanoseconds.
    """

    def __init__(self, stream: BinaryIO, profile: str, library: str, chunk_size: int = 1 << 20,
                 compression_level: int = 3) -> None:
        self._out = stream
        self._chunk_size = chunk_size
        self._compressor = zstandard.ZstdCompressor(level=compression_level)
        self._schemas: list[bytes] = []
        self._channels: list[bytes] = []
        self._channel_counts: dict[int, int] = {}
        self._metadata: list[tuple[str, int, int]] = []
        self._chunk_indexes: list[_ChunkIndex] = []
        self._queued_channel: list[int] = []
        self._queued_time: list[int] = []
        self._queued_data: list[bytes] = []
        self._queued_bytes = 0
        self._message_count = 0
        self._start_ns: int | None = None
        self._end_ns = 0
        self._out.write(MAGIC)
        self._write(_record(_OP["header"], _string(profile) + _string(library)))

    def _write(self, data: bytes) -> int:
        at = self._out.tell()
        self._out.write(data)
        return at

    def register_schema(self, name: str, encoding: str, data: bytes) -> int:
        """A new schema id (from 1) for message type ``name``."""
        schema_id = len(self._schemas) + 1
        body = struct.pack("<H", schema_id) + _string(name) + _string(encoding) + struct.pack("<I", len(data)) + data
        self._schemas.append(_record(_OP["schema"], body))
        return schema_id

    def register_channel(self, topic: str, message_encoding: str, schema_id: int, metadata: dict[str, str]) -> int:
        """A new channel id (from 1) for ``topic``."""
        channel_id = len(self._channels) + 1
        body = struct.pack("<HH", channel_id, schema_id) + _string(topic) + _string(message_encoding) + _map(metadata)
        self._channels.append(_record(_OP["channel"], body))
        self._channel_counts[channel_id] = 0
        return channel_id

    def add_message(self, channel_id: int, log_time_ns: int, data: bytes) -> None:
        """Queue one message (publish time = log time, sequence 0)."""
        self._queued_channel.append(channel_id)
        self._queued_time.append(log_time_ns)
        self._queued_data.append(data)
        self._queued_bytes += len(data) + _MESSAGE_HEAD.itemsize
        if self._queued_bytes >= self._chunk_size:
            self._flush_chunk()

    def add_metadata(self, name: str, items: dict[str, str]) -> None:
        """Write a Metadata record (after the queued messages' chunk)."""
        self._flush_chunk()
        at = self._write(_record(_OP["metadata"], _string(name) + _map(items)))
        self._metadata.append((name, at, self._out.tell() - at))

    def _flush_chunk(self) -> None:
        n = len(self._queued_data)
        if n == 0:
            return
        channel = np.asarray(self._queued_channel, dtype=np.uint16)
        log_time = np.asarray(self._queued_time, dtype=np.uint64)
        sizes = np.fromiter((len(d) for d in self._queued_data), dtype=np.uint64, count=n)
        heads = np.zeros(n, dtype=_MESSAGE_HEAD)
        heads["op"] = _OP["message"]
        heads["length"] = sizes + _MESSAGE_FIXED
        heads["channel"] = channel
        heads["log_time"] = log_time
        heads["publish_time"] = log_time
        prefix = b"".join(self._schemas + self._channels) if not self._chunk_indexes else b""
        record_sizes = sizes + _MESSAGE_HEAD.itemsize
        offsets = len(prefix) + np.concatenate(([0], np.cumsum(record_sizes)[:-1])).astype(np.uint64)
        head_bytes = heads.tobytes()
        size = _MESSAGE_HEAD.itemsize
        parts: list[bytes] = [prefix]
        for i, data in enumerate(self._queued_data):
            parts.append(head_bytes[i * size:(i + 1) * size])
            parts.append(data)
        records = b"".join(parts)
        compressed = self._compressor.compress(records)
        start_ns, end_ns = int(log_time.min()), int(log_time.max())
        body = (struct.pack("<QQQI", start_ns, end_ns, len(records), zlib.crc32(records)) + _string("zstd")
                + struct.pack("<Q", len(compressed)))
        chunk_at = self._write(struct.pack("<BQ", _OP["chunk"], len(body) + len(compressed)) + body)
        self._out.write(compressed)
        chunk_end = self._out.tell()
        index_offsets: list[tuple[int, int]] = []
        for cid in np.flatnonzero(np.bincount(channel)).tolist():  # the channels present (np.unique imports numpy.ma)
            mine = channel == cid
            entries = np.zeros(int(mine.sum()), dtype=_INDEX_ENTRY)
            entries["log_time"] = log_time[mine]
            entries["offset"] = offsets[mine]
            raw = entries.tobytes()
            index_offsets.append((cid, self._write(_record(_OP["message_index"], struct.pack("<HI", cid, len(raw)) + raw))))
            self._channel_counts[cid] += len(entries)
        self._chunk_indexes.append(_ChunkIndex(start_ns, end_ns, chunk_at, chunk_end - chunk_at, index_offsets,
                                               self._out.tell() - chunk_end, len(compressed), len(records)))
        self._message_count += n
        self._start_ns = start_ns if self._start_ns is None else min(self._start_ns, start_ns)
        self._end_ns = max(self._end_ns, end_ns)
        self._queued_channel, self._queued_time, self._queued_data, self._queued_bytes = [], [], [], 0

    def finish(self) -> None:
        """Write the last chunk, the summary section and the footer."""
        self._flush_chunk()
        self._write(_record(_OP["data_end"], struct.pack("<I", 0)))
        summary_start = self._out.tell()
        summary = bytearray()
        groups: list[tuple[int, int, int]] = []

        def group(opcode: int, records: list[bytes]) -> None:
            if records:
                at = summary_start + len(summary)
                summary.extend(b"".join(records))
                groups.append((opcode, at, summary_start + len(summary) - at))

        group(_OP["schema"], self._schemas)
        group(_OP["channel"], self._channels)
        counts = b"".join(struct.pack("<HQ", cid, c) for cid, c in sorted(self._channel_counts.items()))
        stats = (struct.pack("<QHIIII", self._message_count, len(self._schemas), len(self._channels), 0,
                             len(self._metadata), len(self._chunk_indexes))
                 + struct.pack("<QQ", self._start_ns or 0, self._end_ns) + struct.pack("<I", len(counts)) + counts)
        group(_OP["statistics"], [_record(_OP["statistics"], stats)])
        group(_OP["metadata_index"], [_record(_OP["metadata_index"], struct.pack("<QQ", at, length) + _string(name))
                                      for name, at, length in self._metadata])
        group(_OP["chunk_index"], [ci.record() for ci in self._chunk_indexes])
        summary_offset_start = summary_start + len(summary)
        for opcode, at, length in groups:
            summary.extend(_record(_OP["summary_offset"], struct.pack("<BQQ", opcode, at, length)))
        # The summary CRC covers the summary section and the footer up to its own field.
        summary.extend(struct.pack("<BQQQ", _OP["footer"], 8 + 8 + 4, summary_start, summary_offset_start))
        summary.extend(struct.pack("<I", zlib.crc32(summary)))
        self._out.write(bytes(summary))
        self._out.write(MAGIC)
        self._out.flush()
