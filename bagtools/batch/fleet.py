"""The fleet table of a batch: ``fleet.csv``, ``fleet.parquet`` (pyarrow) and ``fleet.png``, one row per bag.

Columns, stable whatever happened: ``bag`` (its directory name), ``path``,
``status`` (ok, skipped: done by an earlier run, failed), ``error`` (the
one-line problem of a failed bag), ``duration_s`` (seconds its job took, in
the run that did it), ``messages`` (in the bag), then the command's headline
numbers (:data:`bagtools.batch.jobs.JOBS`). A value that does not apply is an
empty CSV cell and a Parquet null. The three files are published together,
atomically; they are the batch's own and are replaced by each run.
"""

from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np

from bagtools.batch.jobs import Job
from bagtools.batch.plan import row_columns
from bagtools.batch.task import FAILED, OK, SKIPPED
from bagtools.figures import tidy_layout
from bagtools.outputs import OutputDir

FLEET_FILES = ["fleet.csv", "fleet.parquet", "fleet.png"]
_STATUS_COLOURS = {OK: "tab:green", SKIPPED: "tab:gray", FAILED: "tab:red"}


def preload_fleet_writers() -> None:
    """Import what :func:`write_fleet` needs (matplotlib, pyarrow: about 0.6 s), e.g. while the last bags run."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot  # noqa: F401
    import pyarrow.parquet  # noqa: F401


def fleet_csv(rows: list[dict], columns: list[str]) -> str:
    """The rows as CSV text with a header (None as an empty cell)."""
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=columns, lineterminator="\n")
    writer.writeheader()
    for row in rows:
        writer.writerow({k: ("" if row.get(k) is None else row.get(k)) for k in columns})
    return buffer.getvalue()


def fleet_schema(job: Job):
    """The Parquet schema of ``job``'s table (pyarrow): strings, float64 seconds, int64 counts, the command's types."""
    import pyarrow as pa

    fields = [pa.field("bag", pa.string()), pa.field("path", pa.string()), pa.field("status", pa.string()),
              pa.field("error", pa.string()), pa.field("duration_s", pa.float64()), pa.field("messages", pa.int64())]
    fields += [pa.field(c.name, pa.int64() if c.kind == "int" else pa.float64()) for c in job.columns]
    return pa.schema(fields)


def write_fleet_parquet(path: Path, rows: list[dict], job: Job) -> None:
    """Write the rows as a Parquet file with :func:`fleet_schema`."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    schema = fleet_schema(job)
    table = pa.Table.from_pylist([{k: row.get(k) for k in schema.names} for row in rows], schema=schema)
    pq.write_table(table, path)


def render_fleet_png(path: Path, rows: list[dict], job: Job, title: str) -> None:
    """Bars per bag: its job's duration coloured by status, then one panel per headline group of ``job.plots``.

    A failed bag's column is shaded red in every panel.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Patch

    n = len(rows)
    x = np.arange(n)
    panels = len(job.plots) + 1
    fig, axes = plt.subplots(panels, 1, figsize=(max(8.0, min(24.0, 0.35 * n + 3)), 2.6 * panels + 0.6),
                             sharex=True, squeeze=False)
    axes = axes[:, 0]
    status = [row.get("status") for row in rows]
    failed = np.array([s == FAILED for s in status], dtype=bool)

    def values(name: str) -> np.ndarray:
        return np.array([np.nan if row.get(name) is None else float(row[name]) for row in rows], dtype=float)

    ax = axes[0]
    ax.bar(x, np.nan_to_num(values("duration_s")), color=[_STATUS_COLOURS.get(s, "black") for s in status])
    ax.legend(handles=[Patch(color=colour, label=f"{s} ({status.count(s)})") for s, colour in _STATUS_COLOURS.items()],
              loc="upper right", fontsize=8, ncols=3)
    ax.set_ylabel("job time [s]")
    for ax, (label, names) in zip(axes[1:], job.plots):
        width = 0.8 / len(names)
        for k, name in enumerate(names):
            ax.bar(x + (k - (len(names) - 1) / 2) * width, values(name), width, label=name)
        ax.set_ylabel(label, fontsize=9)
        ax.legend(loc="upper right", fontsize=8, ncols=len(names))
    for ax in axes:
        for i in x[failed]:  # a failed bag has no numbers: its column is shaded in every panel
            ax.axvspan(i - 0.5, i + 0.5, color="tab:red", alpha=0.15, linewidth=0)
        ax.grid(True, axis="y", alpha=0.3)
    last = axes[-1]
    if n <= 60:
        last.set_xticks(x, [row["bag"] for row in rows], rotation=60, ha="right", fontsize=7)
    else:
        last.set_xlabel(f"{n} bags, in the order of fleet.csv")
    axes[0].set_title(title)
    tidy_layout(fig)
    fig.savefig(path, dpi=100)
    plt.close(fig)


def write_fleet(out_dir: str | Path, rows: list[dict], job: Job, title: str) -> list[Path]:
    """Write fleet.csv, fleet.parquet and fleet.png in ``out_dir`` together, replacing the previous run's."""
    columns = row_columns(job)
    with OutputDir(out_dir, FLEET_FILES, force=True) as staged:
        (staged / "fleet.csv").write_text(fleet_csv(rows, columns))
        write_fleet_parquet(staged / "fleet.parquet", rows, job)
        render_fleet_png(staged / "fleet.png", rows, job, title)
    return [Path(out_dir) / name for name in FLEET_FILES]
