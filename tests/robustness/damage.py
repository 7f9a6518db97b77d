"""Byte-level damage of bag files: MCAP, ROS 1 bags and sqlite3 databases.

Each function takes the bytes of a good file and returns damaged bytes; the
``*_layout`` functions find where the records are so that a damage can aim at a
chunk's compressed data, a CRC, an index offset, a schema or a declared size.
Formats: MCAP (https://mcap.dev/spec), ROS 1 bag v2.0
(http://wiki.ros.org/Bags/Format/2.0), SQLite (https://sqlite.org/fileformat.html).
"""

from __future__ import annotations

import random
import struct
import zlib
from dataclasses import dataclass, field

# ---------------------------------------------------------------------------- generic


def truncate(data: bytes, n: int) -> bytes:
    return data[:n]


def zero_run(data: bytes, start: int, length: int) -> bytes:
    """``length`` zero bytes from ``start``, moved forward to the first nonzero byte if the run would change
    nothing there (zeroing an already-zero covariance array is no damage at all)."""
    b = bytearray(data)
    if not any(b[start:start + length]):
        nonzero = next((i for i in range(start, len(b)) if b[i]), None)
        start = start if nonzero is None else nonzero
    end = min(len(b), start + length)
    b[start:end] = bytes(end - start)
    return bytes(b)


def flip_bits(data: bytes, positions: list[int], mask: int = 0x10) -> bytes:
    b = bytearray(data)
    for p in positions:
        b[p] ^= mask
    return bytes(b)


def put(data: bytes, offset: int, fmt: str, *values: int) -> bytes:
    b = bytearray(data)
    struct.pack_into(fmt, b, offset, *values)
    return bytes(b)


def overwrite(data: bytes, offset: int, new: bytes) -> bytes:
    b = bytearray(data)
    b[offset:offset + len(new)] = new
    return bytes(b)


def random_positions(rng: random.Random, start: int, stop: int, k: int) -> list[int]:
    return sorted(rng.randrange(start, stop) for _ in range(k))


def garbage_text(rng: random.Random, n: int) -> bytes:
    """``n`` bytes of printable garbage with some newlines (looks like text, parses as nothing)."""
    alphabet = b"abcdefghijklmnopqrstuvwxyz0123456789[]{}<>=#/_ .:;!?\n"
    return bytes(rng.choice(alphabet) for _ in range(n))


# ---------------------------------------------------------------------------- MCAP

MCAP_MAGIC = b"\x89MCAP0\r\n"
OP_HEADER, OP_FOOTER, OP_SCHEMA, OP_CHANNEL, OP_MESSAGE, OP_CHUNK = 0x01, 0x02, 0x03, 0x04, 0x05, 0x06
OP_MESSAGE_INDEX, OP_CHUNK_INDEX, OP_STATISTICS, OP_SUMMARY_OFFSET, OP_DATA_END = 0x07, 0x08, 0x0B, 0x0E, 0x0F


@dataclass
class McapRecord:
    offset: int   # of the opcode byte
    opcode: int
    length: int   # of the body

    @property
    def body(self) -> int:
        return self.offset + 9

    @property
    def end(self) -> int:
        return self.body + self.length


@dataclass
class McapChunk:
    record: McapRecord
    crc_at: int            # offset of the uncompressed CRC field
    usize_at: int          # offset of the uncompressed size field
    compression: str
    data_at: int           # offset of the compressed records
    data_len: int
    inner: list[McapRecord] = field(default_factory=list)  # records inside (only for uncompressed chunks)


@dataclass
class McapLayout:
    records: list[McapRecord]
    chunks: list[McapChunk]
    footer: McapRecord | None

    def of(self, opcode: int) -> list[McapRecord]:
        return [r for r in self.records if r.opcode == opcode]

    @property
    def summary_start(self) -> int | None:
        data_end = self.of(OP_DATA_END)
        return data_end[0].end if data_end else None


def _walk(data: bytes, start: int, stop: int) -> list[McapRecord]:
    out = []
    off = start
    while off + 9 <= stop:
        op, ln = struct.unpack_from("<BQ", data, off)
        out.append(McapRecord(off, op, ln))
        if op == OP_FOOTER or off + 9 + ln > stop:
            break
        off += 9 + ln
    return out


def mcap_layout(data: bytes) -> McapLayout:
    records = _walk(data, len(MCAP_MAGIC), len(data))
    chunks = []
    for rec in records:
        if rec.opcode != OP_CHUNK:
            continue
        b = rec.body
        comp_len = struct.unpack_from("<I", data, b + 28)[0]
        comp = data[b + 32:b + 32 + comp_len].decode()
        data_len = struct.unpack_from("<Q", data, b + 32 + comp_len)[0]
        data_at = b + 40 + comp_len
        chunk = McapChunk(rec, b + 24, b + 16, comp, data_at, data_len)
        if comp == "":
            chunk.inner = _walk(data, data_at, data_at + data_len)
        chunks.append(chunk)
    footers = [r for r in records if r.opcode == OP_FOOTER]
    return McapLayout(records, chunks, footers[0] if footers else None)


def chunk_records(data: bytes, chunk: McapChunk) -> bytes:
    """The decompressed records of a chunk."""
    raw = data[chunk.data_at:chunk.data_at + chunk.data_len]
    if chunk.compression == "zstd":
        import zstandard

        size = struct.unpack_from("<Q", data, chunk.usize_at)[0]
        return zstandard.ZstdDecompressor().decompress(raw, max_output_size=size)
    if chunk.compression == "":
        return raw
    raise ValueError(chunk.compression)


def with_correct_crc(data: bytes, chunk: McapChunk) -> bytes:
    """Set the chunk's CRC to the true CRC32 of its records (so later damage is detectable)."""
    return put(data, chunk.crc_at, "<I", zlib.crc32(chunk_records(data, chunk)))


def chunk_index_fields(data: bytes, rec: McapRecord) -> dict[str, int]:
    """Offsets of the fixed fields of a ChunkIndex record."""
    b = rec.body
    mio_len = struct.unpack_from("<I", data, b + 32)[0]
    after = b + 36 + mio_len
    comp_len = struct.unpack_from("<I", data, after + 8)[0]
    return {"chunk_start_offset": b + 16, "chunk_length": b + 24, "message_index_length": after,
            "compressed_size": after + 12 + comp_len, "uncompressed_size": after + 20 + comp_len}


def schema_fields(data: bytes, rec: McapRecord) -> dict[str, tuple[int, int]]:
    """(offset of the u32 length, length) of a Schema record's name, encoding and data."""
    p = rec.body + 2
    out = {}
    for name in ("name", "encoding", "data"):
        n = struct.unpack_from("<I", data, p)[0]
        out[name] = (p, n)
        p += 4 + n
    return out


def channel_fields(data: bytes, rec: McapRecord) -> dict[str, tuple[int, int]]:
    """Offsets of a Channel record: schema_id (offset, 2) and (u32 length offset, length) of topic and encoding."""
    b = rec.body
    out = {"schema_id": (b + 2, 2)}
    p = b + 4
    for name in ("topic", "message_encoding"):
        n = struct.unpack_from("<I", data, p)[0]
        out[name] = (p, n)
        p += 4 + n
    return out


# ---------------------------------------------------------------------------- ROS 1 bags

ROS1_MAGIC = b"#ROSBAG V2.0\n"


@dataclass
class Ros1Record:
    offset: int         # of the header length
    op: int
    header_len: int
    data_len: int
    fields: dict[str, tuple[int, int]]  # name -> (offset of the field's u32 length, value length)

    @property
    def data_len_at(self) -> int:
        return self.offset + 4 + self.header_len

    @property
    def data_at(self) -> int:
        return self.data_len_at + 4

    @property
    def end(self) -> int:
        return self.data_at + self.data_len


def ros1_layout(data: bytes) -> list[Ros1Record]:
    out = []
    off = len(ROS1_MAGIC)
    while off + 8 <= len(data):
        hl = struct.unpack_from("<I", data, off)[0]
        if off + 8 + hl > len(data):
            break
        fields: dict[str, tuple[int, int]] = {}
        p = off + 4
        op = -1
        while p < off + 4 + hl:
            fl = struct.unpack_from("<I", data, p)[0]
            raw = data[p + 4:p + 4 + fl]
            name, _, value = raw.partition(b"=")
            fields[name.decode("latin-1")] = (p, fl)
            if name == b"op":
                op = value[0]
            p += 4 + fl
        dl = struct.unpack_from("<I", data, off + 4 + hl)[0]
        out.append(Ros1Record(off, op, hl, dl, fields))
        off += 8 + hl + dl
    return out


def ros1_field_value_at(rec: Ros1Record, name: str) -> int:
    """Offset of a header field's value (after 'name=')."""
    p, _ = rec.fields[name]
    return p + 4 + len(name) + 1


# ---------------------------------------------------------------------------- sqlite3


def sqlite_page_size(data: bytes) -> int:
    size = struct.unpack_from(">H", data, 16)[0]
    return 65536 if size == 1 else size
