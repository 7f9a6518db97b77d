"""Table files, written a chunk of rows at a time: CSV (csv module), Parquet (pyarrow) and NPZ (numpy).

Every value is written exactly, in its column's own type (int64 and uint64 as
integers, float32 and float64 at their own precision, NaN and infinities kept;
CSV writes each float in the shortest text that reads back to the same value).

List columns (a scan's ranges, an odometry covariance): Parquet keeps them as
list columns and NPZ as 2-D arrays; a list whose length varies from row to row
is padded (NaN for floats, 0 for integers and False for booleans) and its
lengths are in ``NAME.length``. CSV spreads them over numbered columns
``ranges.0``, ``ranges.1``, ... as wide as the first row's list (shorter lists
leave empty cells; a longer one is refused: use Parquet or NPZ for scans
whose beam count changes). Columns are fixed by the first chunk; a later
message without one of them gets an empty value (NaN in NPZ).
"""

from __future__ import annotations

import csv
from pathlib import Path
from typing import Protocol

import numpy as np

from bagtools.errors import BagtoolsError
from bagtools.commands.export.tables import Chunk

FORMATS = {".csv": "csv", ".parquet": "parquet", ".npz": "npz"}
PARQUET_BATCH_ROWS = 65_536


class Sink(Protocol):
    """Where the rows go."""

    def write(self, chunk: Chunk) -> None: ...

    def close(self) -> None: ...


def is_ragged(column: np.ndarray) -> bool:
    """A column of lists whose length may vary (an object array of 1-D arrays)."""
    return column.dtype == object and column.ndim == 1 and column.size > 0 and isinstance(column[0], np.ndarray)


def _rows(chunk: Chunk) -> int:
    return len(next(iter(chunk.values()))) if chunk else 0


def _fill(template: np.ndarray, n: int) -> np.ndarray:
    """n empty values shaped like a column: NaN for floats, 0 for integers, '' for strings, empty lists."""
    if is_ragged(template):
        out = np.empty(n, dtype=object)
        for i in range(n):
            out[i] = np.empty(0, dtype=template[0].dtype)
        return out
    shape = (n,) + template.shape[1:]
    if template.dtype.kind == "f":
        return np.full(shape, np.nan, dtype=template.dtype)
    if template.dtype == object:
        return np.full(shape, "", dtype=object)
    return np.zeros(shape, dtype=template.dtype)


class _Columns:
    """Keeps every chunk to the first chunk's columns (see the module docstring)."""

    def __init__(self) -> None:
        self.templates: dict[str, np.ndarray] | None = None
        self.filled: dict[str, int] = {}

    def conform(self, chunk: Chunk) -> Chunk:
        if self.templates is None:
            self.templates = {name: column[:1] for name, column in chunk.items()}
            return chunk
        n = _rows(chunk)
        out = {}
        for name, template in self.templates.items():
            if name in chunk:
                out[name] = chunk[name]
            else:
                self.filled[name] = self.filled.get(name, 0) + 1
                out[name] = _fill(template, n)
        return out


class CsvSink:
    """CSV with a header row; float32 values in their shortest form, stamps as exact integers."""

    def __init__(self, path: Path) -> None:
        self._file = open(path, "w", newline="", encoding="utf-8")
        self._writer = csv.writer(self._file)
        self._columns = _Columns()
        self._widths: dict[str, int] = {}

    def write(self, chunk: Chunk) -> None:
        chunk = self._columns.conform(chunk)
        if not self._widths:
            header = []
            for name, column in chunk.items():
                width = len(column[0]) if is_ragged(column) else (column.shape[1] if column.ndim == 2 else 0)
                self._widths[name] = width
                header += [f"{name}.{i}" for i in range(width)] if column.ndim == 2 or is_ragged(column) else [name]
            self._writer.writerow(header)
        cells: list[list] = []
        for name, column in chunk.items():
            width = self._widths[name]
            if is_ragged(column):
                cells += self._ragged(name, column, width)
            elif column.ndim == 2:
                cells += [_text(column[:, i]) for i in range(column.shape[1])]
            else:
                cells.append(_text(column))
        self._writer.writerows(zip(*cells))

    def _ragged(self, name: str, column: np.ndarray, width: int) -> list[list]:
        lengths = [len(v) for v in column]
        if max(lengths, default=0) > width:
            raise BagtoolsError(f"a message has {max(lengths)} values in {name}, more than the {width} of the first: "
                                "CSV columns are fixed by the first message; export to .parquet or .npz instead")
        rows = [_text(values) + [""] * (width - len(values)) for values in column]
        return [list(cells) for cells in zip(*rows)] if rows and width else [[] for _ in range(width)]

    def close(self) -> None:
        self._file.close()


def _text(column: np.ndarray) -> list:
    """Cell values: float32 in their shortest decimal form, everything else as Python values (float64 in its
    shortest round-trip form, integers exactly)."""
    if column.dtype == np.float32:
        return column.astype(str).tolist()
    return column.tolist()


class ParquetSink:
    """Parquet (pyarrow), row groups of about PARQUET_BATCH_ROWS rows; lists as list columns."""

    def __init__(self, path: Path) -> None:
        try:
            import pyarrow  # noqa: F401
            import pyarrow.parquet  # noqa: F401
        except ImportError as err:
            raise BagtoolsError("writing .parquet needs pyarrow (pip install pyarrow)", path) from err
        self.path = path
        self._writer = None
        self._pending: list[Chunk] = []
        self._rows = 0
        self._columns = _Columns()

    def write(self, chunk: Chunk) -> None:
        chunk = self._columns.conform(chunk)
        self._pending.append(chunk)
        self._rows += _rows(chunk)
        if self._rows >= PARQUET_BATCH_ROWS:
            self._flush()

    def _flush(self) -> None:
        import pyarrow as pa
        import pyarrow.parquet as pq

        if not self._pending:
            return
        names = list(self._pending[0])
        arrays = [_arrow_column([c[name] for c in self._pending]) for name in names]
        table = pa.Table.from_arrays(arrays, names=names)
        if self._writer is None:
            self._writer = pq.ParquetWriter(self.path, table.schema)
        self._writer.write_table(table.cast(self._writer.schema))
        self._pending, self._rows = [], 0

    def close(self) -> None:
        self._flush()
        if self._writer is not None:
            self._writer.close()


def _arrow_column(parts: list[np.ndarray]):
    import pyarrow as pa

    if is_ragged(parts[0]):
        lists = [v for part in parts for v in part]
        offsets = np.zeros(len(lists) + 1, dtype=np.int64)
        np.cumsum([len(v) for v in lists], out=offsets[1:])
        values = np.concatenate(lists) if lists else np.empty(0, dtype=parts[0][0].dtype)
        return pa.LargeListArray.from_arrays(pa.array(offsets), pa.array(values))
    column = np.concatenate(parts)
    if column.ndim == 2:
        return pa.FixedSizeListArray.from_arrays(pa.array(np.ascontiguousarray(column).reshape(-1)), column.shape[1])
    if column.dtype == object:
        return pa.array(column.tolist(), type=pa.string())
    return pa.array(column)


class NpzSink:
    """NPZ (numpy, compressed), one array per column, loadable without pickle; built in memory, written at the end.

    Text columns take one of three forms, the smallest that holds them: a fixed-width string array ``NAME``; when
    values repeat, each stored once: ``NAME`` holds each row's index into ``NAME.values``
    (``npz["frame_id.values"][npz["frame_id"]]`` gives the column back); when a few long texts would pad every
    row to their width, ``NAME.utf8`` (the texts' UTF-8 bytes, one after another) and ``NAME.offsets`` (int64,
    rows + 1: row i is ``utf8[offsets[i]:offsets[i + 1]]``)."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self._parts: dict[str, list[np.ndarray]] = {}
        self._columns = _Columns()

    def write(self, chunk: Chunk) -> None:
        for name, column in self._columns.conform(chunk).items():
            self._parts.setdefault(name, []).append(column)

    def close(self) -> None:
        arrays: dict[str, np.ndarray] = {}
        for name, parts in self._parts.items():
            if is_ragged(parts[0]):
                arrays[name], lengths = _padded(parts)
                if lengths.size and (lengths != lengths[0]).any():
                    arrays[f"{name}.length"] = lengths
                continue
            column = np.concatenate(parts)
            if column.dtype == object:
                arrays.update(_text_arrays(name, column))
            else:
                arrays[name] = column
        with open(self.path, "wb") as f:
            np.savez_compressed(f, **arrays)


def _padded(parts: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Ragged lists as one 2-D array (padded with NaN, 0 or False) and each row's length."""
    lists = [v for part in parts for v in part]
    lengths = np.array([len(v) for v in lists], dtype=np.int64)
    dtype = parts[0][0].dtype
    out = np.full((len(lists), int(lengths.max(initial=0))), np.nan if dtype.kind == "f" else 0, dtype=dtype)
    for i, values in enumerate(lists):
        out[i, :len(values)] = values
    return out, lengths


def _text_arrays(name: str, column: np.ndarray) -> dict[str, np.ndarray]:
    """A text column in the smallest of its three forms (see :class:`NpzSink`)."""
    encoded = [str(v).encode("utf-8") for v in column]
    lengths = np.array([len(b) for b in encoded], dtype=np.int64)
    padded_bytes = 4 * column.size * int(lengths.max(initial=0))  # a fixed-width array: 4 bytes per character
    if padded_bytes > 4 * int(lengths.sum()) + (1 << 20):  # mostly padding: a few long texts
        offsets = np.zeros(column.size + 1, dtype=np.int64)
        np.cumsum(lengths, out=offsets[1:])
        return {f"{name}.utf8": np.frombuffer(b"".join(encoded), dtype=np.uint8), f"{name}.offsets": offsets}
    text = column.astype(str)
    if text.size:
        values, index = np.unique(text, return_inverse=True)
        if values.size <= text.size // 2:  # values repeat: each stored once, rows index them
            return {name: index.astype(np.int32 if values.size > 32_767 else np.int16), f"{name}.values": values}
    return {name: text}


class Batched:
    """Gathers small chunks (a message's row or few) into batches of about ``rows`` rows before a sink writes them:
    the per-call cost of the sinks is paid once per batch, not once per message."""

    def __init__(self, sink: Sink, rows: int = 8192) -> None:
        self.sink = sink
        self.rows = rows
        self.columns = _Columns()
        self._pending: list[Chunk] = []
        self._count = 0

    def write(self, chunk: Chunk) -> None:
        self._pending.append(self.columns.conform(chunk))
        self._count += _rows(chunk)
        if self._count >= self.rows:
            self._flush()

    def _flush(self) -> None:
        if self._pending:
            names = list(self._pending[0])
            self.sink.write({name: np.concatenate([c[name] for c in self._pending]) for name in names})
        self._pending, self._count = [], 0

    def close(self) -> None:
        try:
            self._flush()
        except BaseException:
            close_quietly(self.sink)  # the flush's failure (a full disk) is what happened, not the close's after it
            raise
        self.sink.close()


def close_quietly(sink: Sink | Batched) -> None:
    """Close ``sink`` after a failure, ignoring what closing a half-written file says about itself."""
    try:
        sink.close()
    except Exception:
        pass


def open_sink(path: Path, fmt: str) -> Batched:
    """The sink writing ``fmt`` ('csv', 'parquet' or 'npz') to ``path``, batched."""
    return Batched({"csv": CsvSink, "parquet": ParquetSink, "npz": NpzSink}[fmt](path))
