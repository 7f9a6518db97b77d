"""Exporting one topic: read it message by message, turn each into rows, hand them to the file's sink."""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import partial
from pathlib import Path

from bagtools.errors import BagtoolsError, TopicError
from bagtools.commands.export.sinks import FORMATS, close_quietly, is_ragged, open_sink
from bagtools.commands.export.tables import ROWS, message_rows, pointcloud2_rows
from bagtools.io import open_bag
from bagtools.outputs import atomic_path, check_writable
from bagtools.progress import progress


@dataclass
class ExportSummary:
    """What was written: messages read, rows, the columns (as the file names them; in CSV a list column NAME is
    spread over NAME.0, NAME.1, ...), which of them hold lists, and warnings."""

    path: Path
    format: str
    msgtype: str
    messages: int = 0
    rows: int = 0
    columns: list[str] = field(default_factory=list)
    list_columns: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)


def output_format(out: str | Path) -> str:
    """'csv', 'parquet' or 'npz' from the suffix of ``out`` (raises :class:`BagtoolsError` for another)."""
    fmt = FORMATS.get(Path(out).suffix.lower())
    if fmt is None:
        raise BagtoolsError(f"unknown output format {Path(out).suffix or '(no suffix)'!r}: name the file .csv, "
                            ".parquet or .npz", out)
    return fmt


def export_topic(bag_path: str | Path, topic: str, out: str | Path, force: bool = False,
                 keep_nan: bool = False) -> ExportSummary:
    """Write every message of ``topic`` as rows into ``out`` (format by suffix), atomically. ``keep_nan``: keep a
    PointCloud2's points with a non-finite coordinate (dropped by default).

    Refuses an existing ``out`` without ``force`` and a topic the bag lacks or that has no message, before any
    work. Every message type is read (see :mod:`bagtools.commands.export.tables`).
    """
    out = Path(out)
    check_writable(out, force, inputs=[bag_path])
    fmt = output_format(out)
    with open_bag(bag_path) as bag:
        info = bag.require_topic(topic)
        if info.count == 0:
            raise TopicError(f"topic '{topic}' ({info.msgtype}) has no messages, so there is nothing to export",
                             bag.path)
        rows_of = ROWS.get(info.msgtype) or partial(message_rows, definitions=bag.field_definitions)
        if rows_of is pointcloud2_rows:
            rows_of = partial(pointcloud2_rows, keep_nan=keep_nan)
        summary = ExportSummary(out, fmt, info.msgtype)
        with atomic_path(out, force, inputs=[bag_path]) as staged:
            sink = open_sink(staged, fmt)
            try:
                for rec in progress(bag.messages([topic]), total=info.count, desc="exporting", unit="msg"):
                    chunk = rows_of(rec)
                    if not summary.columns:
                        summary.columns = list(chunk)
                        summary.list_columns = [name for name, column in chunk.items()
                                                if column.ndim == 2 or is_ragged(column)]
                    sink.write(chunk)
                    summary.messages += 1
                    summary.rows += len(chunk["stamp_ns"])
            except BaseException:
                close_quietly(sink)  # the first failure is what happened (a full disk); closing only fails again
                raise
            sink.close()
            if summary.messages == 0:
                raise BagtoolsError(f"no message on {topic} could be read, so there is nothing to export", bag.path)
        summary.warnings = list(bag.warnings) + [
            f"{n} message(s) on {topic} lack the column {name} of the first; left empty"
            for name, n in sink.columns.filled.items()]
    return summary
