"""One bag's job as it runs on a worker, its row of the fleet table, and the completion marker that makes reruns resume.

:func:`run_task` is the error boundary of a bag: it never raises for a
problem with the bag. A :class:`~bagtools.errors.BagtoolsError` (not a bag,
a missing topic, outputs that exist) makes the row ``failed`` with the same
one line the single command prints; any other exception is a bug and the row
says ``internal error: Type: message``. Only the loss of the worker itself
(killed, out of memory) escapes, and Dask runs the task again elsewhere.

On success, after the command's writer has published its files, a small
marker ``DIR/<bag>/.batch-done`` (JSON: the bag, the command, its settings,
the files written and the row) is written atomically, last. A rerun skips a
bag whose marker matches and whose files are all there (:func:`completed_row`).
"""

from __future__ import annotations

import io
import json
import time
from contextlib import redirect_stderr
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from bagtools.errors import BagtoolsError

#: The completion marker in each bag's output directory, written last and only on success.
MARKER = ".batch-done"
MARKER_VERSION = 1

#: The first columns of every fleet table, in this order; a command's own columns follow.
COMMON_COLUMNS = ("bag", "path", "status", "error", "duration_s", "messages")
OK, SKIPPED, FAILED = "ok", "skipped", "failed"


@dataclass(frozen=True)
class BagTask:
    """One bag's job, as shipped to a worker (picklable).

    ``name``: its directory under the batch's output directory ``out_dir``.
    ``options``: the library options object of the command. ``settings``:
    the command's parameters as JSON data, recorded in the marker so that a
    rerun with other options does not take old outputs for done.
    """

    command: str
    bag: str
    name: str
    out_dir: str
    options: Any
    settings: dict
    force: bool

    @property
    def bag_dir(self) -> Path:
        """Where this bag's outputs go: ``out_dir/name``."""
        return Path(self.out_dir) / self.name


def new_row(task: BagTask, status: str, error: str = "", duration_s: float | None = None,
            messages: int | None = None) -> dict:
    """A fleet-table row with the common columns; the command's columns are added by the caller."""
    return {"bag": task.name, "path": task.bag, "status": status, "error": error, "duration_s": duration_s,
            "messages": messages}


def one_line(text: str, limit: int = 500) -> str:
    """``text`` on one line, at most ``limit`` characters."""
    flat = " ".join(str(text).split())
    return flat if len(flat) <= limit else flat[: limit - 3] + "..."


def error_line(exc: BaseException, bag: str) -> str:
    """The one-line problem of a failed bag, as ``bagtools <command>`` would print it (without ``bagtools: ``)."""
    if isinstance(exc, BagtoolsError):
        return one_line(str(exc) if exc.path else f"{bag}: {exc.problem}")
    if isinstance(exc, MemoryError):
        return f"{bag}: out of memory (is the bag damaged, or an option too large?)"
    if isinstance(exc, OSError):
        return one_line(f"{exc.filename or bag}: {exc.strerror or exc}")
    return one_line(f"internal error: {type(exc).__name__}: {exc}")


def _mcap_summary_count(files: list[Path]) -> int | None:
    """Messages the summary statistics of these MCAP files count (footer and summary only), or None if any lacks them."""
    from mcap.reader import make_reader

    total = 0
    for path in files:
        try:
            with path.open("rb") as f:
                summary = make_reader(f).get_summary()
        except Exception:  # no summary (a cut file), or not MCAP at all: the reader will say what it is
            return None
        if summary is None or summary.statistics is None:
            return None
        total += summary.statistics.message_count
    return total


def message_count(bag: str) -> int:
    """Messages in ``bag``: from its MCAP summaries when every storage file has one, else counted by the reader.

    The summaries are read in a millisecond; the reader scans every chunk
    (a tenth of a second for a minute of a TurtleBot) and raises
    :class:`~bagtools.errors.BagError` for a bag it cannot read.
    """
    from bagtools.io import open_bag

    path = Path(bag)
    files = sorted(p for p in path.iterdir() if p.suffix in (".mcap", ".db3")) if path.is_dir() else [path]
    if files and all(p.suffix == ".mcap" for p in files):
        counted = _mcap_summary_count(files)
        if counted is not None:
            return counted
    with open_bag(bag) as reader:
        return reader.message_count


def run_task(task: BagTask) -> dict:
    """Run ``task`` on this process and return its row (never raises for a problem with the bag).

    Progress bars and warnings the pipelines print go nowhere: a worker's
    stderr is not the user's terminal, and every warning is in summary.json.
    """
    from bagtools.batch.jobs import JOBS

    job = JOBS[task.command]
    t0 = time.perf_counter()
    messages = None
    try:
        with redirect_stderr(io.StringIO()):
            if not job.counts_messages:
                messages = message_count(task.bag)
            out = job.run(task.bag, task.bag_dir, task.options, task.force)
            messages = out.messages if job.counts_messages else messages
            row = new_row(task, OK, "", round(time.perf_counter() - t0, 3), messages)
            row.update({c.name: c.value(out.summary) for c in job.columns})
            write_marker(task, row, out.written)
    except Exception as exc:  # the bag's boundary: a failed bag is a row, never the end of the batch
        row = new_row(task, FAILED, error_line(exc, task.bag), round(time.perf_counter() - t0, 3), messages)
        row.update({c.name: None for c in job.columns})
    return row


def write_marker(task: BagTask, row: dict, written: list[str]) -> None:
    """Write ``bag_dir/.batch-done`` atomically: the bag is complete."""
    from bagtools.outputs import write_text_atomic

    marker = {"version": MARKER_VERSION, "bag": task.bag, "command": task.command, "settings": task.settings,
              "files": sorted(written), "finished": datetime.now(UTC).isoformat(timespec="seconds"), "row": row}
    write_text_atomic(task.bag_dir / MARKER, json.dumps(marker, indent=1) + "\n", force=True)


def read_marker(bag_dir: Path) -> dict | None:
    """The marker of ``bag_dir`` as a dict, or None when there is none (or it is unreadable)."""
    try:
        marker = json.loads((bag_dir / MARKER).read_text())
    except (OSError, ValueError):
        return None
    return marker if isinstance(marker, dict) and marker.get("version") == MARKER_VERSION else None


class ForeignOutputError(BagtoolsError):
    """A bag's output directory holds the outputs of another bag (never replaced, even with --force)."""


def check_owner(task: BagTask, marker: dict | None) -> None:
    """Raise :class:`ForeignOutputError` if ``marker`` (of ``task.bag_dir``) belongs to another bag."""
    if marker is not None and marker.get("bag") != task.bag:
        raise ForeignOutputError(f"holds the outputs of another bag ({marker.get('bag')}); use another --out",
                                 task.bag_dir)


def completed_row(task: BagTask, marker: dict | None) -> dict | None:
    """The ``skipped`` row of a bag whose outputs are complete for this command and settings, else None.

    Complete: ``marker`` (read from ``task.bag_dir``) names this bag, this
    command and these settings, and every file it lists is there.
    """
    if marker is None or marker.get("bag") != task.bag:
        return None
    if marker.get("command") != task.command or marker.get("settings") != task.settings:
        return None
    files, row = marker.get("files"), marker.get("row")
    if not isinstance(files, list) or not isinstance(row, dict):
        return None
    if not all((task.bag_dir / name).is_file() for name in files):
        return None
    return {**row, "bag": task.name, "path": task.bag, "status": SKIPPED, "error": ""}
