"""`bagtools export` writes every value exactly, in its field's own type, in CSV, Parquet and NPZ alike."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

import bagtools.commands.export.sinks as sinks
from bagtools.commands.export import export_topic
from bagtools.io import open_bag

MSGTYPE = "bagtools_test/msg/Extremes"
DEFINITION = """
bool b
byte by
char ch
int8 i8
uint8 u8
int16 i16
uint16 u16
int32 i32
uint32 u32
int64 i64
uint64 u64
float32 f32
float64 f64
string text
float64[] f64_seq
float32[3] f32_arr
int64[] i64_seq
uint64[2] u64_arr
bool[] bool_seq
int16[] i16_seq
uint32[] u32_seq
uint8[4] u8_arr
uint8[] blob
float64 stamp_ns
string frame_id
uint64 log_time_ns
"""
DTYPES = {"b": np.bool_, "by": np.int8, "ch": np.uint8, "i8": np.int8, "u8": np.uint8, "i16": np.int16,
          "u16": np.uint16, "i32": np.int32, "u32": np.uint32, "i64": np.int64, "u64": np.uint64, "f32": np.float32,
          "f64": np.float64, "msg.stamp_ns": np.float64, "msg.log_time_ns": np.uint64}
LISTS = {"f64_seq": np.float64, "f32_arr": np.float32, "i64_seq": np.int64, "u64_arr": np.uint64,
         "bool_seq": np.bool_, "i16_seq": np.int16, "u32_seq": np.uint32, "u8_arr": np.uint8}
I64, U64 = np.iinfo(np.int64), np.iinfo(np.uint64)
F32, F64 = np.finfo(np.float32), np.finfo(np.float64)


def _store():
    store = get_typestore(Stores.ROS2_HUMBLE)
    store.register(get_types_from_msg(DEFINITION, MSGTYPE))
    return store


def _messages(store) -> list:
    T = store.types[MSGTYPE]
    a = np.array
    return [
        T(b=True, by=-128, ch=255, i8=-128, u8=255, i16=-32768, u16=65535, i32=-2**31, u32=2**32 - 1, i64=I64.min,
          u64=1, f32=float(F32.smallest_subnormal), f64=float(F64.smallest_subnormal), text="tab\tcomma, \"quote\"",
          f64_seq=a([1e-50, math.nan, math.inf, -math.inf, -0.0, F64.max, 5e-324]),
          f32_arr=a([F32.max, F32.smallest_subnormal, np.nan], dtype=np.float32),
          i64_seq=a([I64.max, I64.min, 16777217, 1700000000123456789]), u64_arr=a([U64.max, 0], dtype=np.uint64),
          bool_seq=a([True, False, True]), i16_seq=a([32767, -32768], dtype=np.int16),
          u32_seq=a([2**32 - 1, 0], dtype=np.uint32),
          u8_arr=a([0, 1, 254, 255], dtype=np.uint8), blob=a(range(100), dtype=np.uint8), stamp_ns=0.1,
          frame_id="own", log_time_ns=U64.max),
        T(b=False, by=127, ch=0, i8=127, u8=0, i16=32767, u16=0, i32=2**31 - 1, u32=0, i64=I64.max, u64=U64.max,
          f32=float(F32.max), f64=-math.inf, text="", f64_seq=a([0.1]), f32_arr=a([-0.0, 1.1, -F32.max], np.float32),
          i64_seq=a([], dtype=np.int64), u64_arr=a([2**63, 2**53 + 1], dtype=np.uint64), bool_seq=a([], dtype=bool),
          i16_seq=a([-1], dtype=np.int16), u32_seq=a([], dtype=np.uint32),
          u8_arr=a([9, 9, 9, 9], dtype=np.uint8), blob=a([], dtype=np.uint8), stamp_ns=math.nan, frame_id="",
          log_time_ns=0),
    ]


@pytest.fixture(scope="module")
def extremes_bag(tmp_path_factory) -> tuple[Path, list]:
    store = _store()
    msgs = _messages(store)
    path = tmp_path_factory.mktemp("extremes") / "bag"
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conn = writer.add_connection("/extremes", MSGTYPE, typestore=store)
        for k, msg in enumerate(msgs):
            writer.write(conn, 1_000 + k, store.serialize_cdr(msg, MSGTYPE))
    with open_bag(path) as bag:  # what rosbags deserializes, the reference
        read = [rec.msg for rec in bag.messages(["/extremes"])]
    return path, read


def _expected(msgs: list, name: str) -> list:
    field = name.removeprefix("msg.")
    return [getattr(m, field) for m in msgs]


def _same(values, expected, dtype) -> bool:
    """Bit for bit in ``dtype`` (NaN payloads and the sign of zero included)."""
    got = np.asarray(values, dtype=dtype)
    want = np.asarray(expected, dtype=dtype)
    return got.shape == want.shape and got.tobytes() == want.tobytes()


def _cell(text: str, dtype) -> object:
    if dtype is np.bool_:
        return {"True": True, "False": False}[text]
    return float(text) if np.dtype(dtype).kind == "f" else int(text)


def test_csv_exact(tmp_path: Path, extremes_bag) -> None:
    bag, msgs = extremes_bag
    export_topic(bag, "/extremes", tmp_path / "x.csv")
    with open(tmp_path / "x.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert [r["stamp_ns"] for r in rows] == ["1000", "1001"] and [r["frame_id"] for r in rows] == ["", ""]
    for name, dtype in DTYPES.items():
        assert _same([_cell(r[name], dtype) for r in rows], _expected(msgs, name), dtype), name
    for name, dtype in LISTS.items():
        for r, want in zip(rows, _expected(msgs, name)):
            cells = [r[k] for k in r if k.startswith(f"{name}.")]
            assert _same([_cell(c, dtype) for c in cells if c != ""], want, dtype), name
    assert [r["text"] for r in rows] == _expected(msgs, "text")
    assert [r["msg.frame_id"] for r in rows] == ["own", ""] and [r["blob.bytes"] for r in rows] == ["100", "0"]


def test_parquet_exact_and_typed(tmp_path: Path, extremes_bag, monkeypatch) -> None:
    bag, msgs = extremes_bag
    monkeypatch.setattr(sinks, "PARQUET_BATCH_ROWS", 1)  # every message its own record batch
    export_topic(bag, "/extremes", tmp_path / "x.parquet")
    table = pq.read_table(tmp_path / "x.parquet")
    assert table.schema.field("u64").type == pa.uint64() and table.schema.field("i8").type == pa.int8()
    assert table.schema.field("stamp_ns").type == pa.int64() and table.column("stamp_ns").to_pylist() == [1000, 1001]
    for name, dtype in DTYPES.items():
        assert table.schema.field(name).type == pa.from_numpy_dtype(dtype), name
        assert _same(table.column(name).to_numpy(), _expected(msgs, name), dtype), name
    for name, dtype in LISTS.items():
        assert table.schema.field(name).type.value_type == pa.from_numpy_dtype(dtype), name
        for got, want in zip(table.column(name).to_pylist(), _expected(msgs, name)):
            assert _same(got, want, dtype), name


def test_npz_exact_and_typed(tmp_path: Path, extremes_bag) -> None:
    bag, msgs = extremes_bag
    export_topic(bag, "/extremes", tmp_path / "x.npz")
    with np.load(tmp_path / "x.npz") as npz:
        for name, dtype in DTYPES.items():
            assert npz[name].dtype == dtype and _same(npz[name], _expected(msgs, name), dtype), name
        for name, dtype in LISTS.items():
            column = npz[name]
            lengths = npz[f"{name}.length"] if f"{name}.length" in npz else [column.shape[1]] * len(column)
            assert column.dtype == dtype, name
            for row, n, want in zip(column, lengths, _expected(msgs, name)):
                assert _same(row[:n], want, dtype), name
        assert npz["i64_seq.length"].tolist() == [4, 0] and npz["u32_seq"].tolist() == [[2**32 - 1, 0], [0, 0]]


def test_npz_a_few_long_texts_are_not_padded(tmp_path: Path) -> None:
    """One 4 MB string among 3000 short ones: stored as UTF-8 bytes and offsets, not a 48 GB fixed-width array."""
    store = get_typestore(Stores.ROS2_HUMBLE)
    String = store.types["std_msgs/msg/String"]
    texts = [f"short {k} é" for k in range(3000)]
    texts[1234] = "x" * 4_000_000
    path = tmp_path / "bag"
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conn = writer.add_connection("/text", "std_msgs/msg/String", typestore=store)
        for k, text in enumerate(texts):
            writer.write(conn, 1 + k, store.serialize_cdr(String(data=text), "std_msgs/msg/String"))
    export_topic(path, "/text", tmp_path / "t.npz")
    with np.load(tmp_path / "t.npz") as npz:
        utf8, offsets = npz["data.utf8"], npz["data.offsets"]
        back = [utf8[a:b].tobytes().decode() for a, b in zip(offsets[:-1], offsets[1:])]
    assert back == texts
