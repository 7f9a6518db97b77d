"""What a batch will do, decided before any work: the bags, their directories, which are already done.

``plan_batch`` checks everything a user can get wrong up front (the command,
its options, the bags, the output directory), so that a bad argument is exit
status 2 before a worker starts. It reads the completion markers: bags whose
outputs are complete are ``skipped`` rows (unless ``force``), the others become
:class:`~bagtools.batch.task.BagTask` objects to run.

The output directory belongs to one command: a manifest,
``DIR/.bagtools-batch.json``, records it, and a rerun with another command
is refused (the bags' directories would mix two commands' files). While a
batch runs it holds ``DIR/.bagtools-batch.lock``: a second batch into the same
directory at once is refused, and the first runs.
"""

from __future__ import annotations

import fcntl
import json
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from bagtools.batch.bags import BATCH_LOCK, BATCH_MANIFEST, RESERVED_NAMES, find_bags, output_names
from bagtools.batch.jobs import Job, get_job
from bagtools.batch.task import (
    COMMON_COLUMNS, FAILED, BagTask, ForeignOutputError, check_owner, completed_row, new_row, read_marker,
)
from bagtools.errors import BagtoolsError
from bagtools.outputs import refuse_input_overlap


@dataclass
class BatchPlan:
    """A batch before it runs.

    ``bags``: every bag, in argument order, with its directory name.
    ``tasks``: the bags to run. ``decided``: rows known without running
    (``skipped``: complete from an earlier run; ``failed``: a directory that
    holds another bag's outputs), keyed by bag name.
    """

    command: str
    job: Job
    out_dir: Path
    force: bool
    bags: list[tuple[Path, str]]
    tasks: list[BagTask] = field(default_factory=list)
    decided: dict[str, dict] = field(default_factory=dict)
    lock_fd: int | None = None  # the output directory's batch lock, held while the plan lives (lock_out_dir)
    created: list[Path] = field(default_factory=list)  # folders and files this run made that hold no result

    @property
    def total(self) -> int:
        return len(self.bags)

    def release(self) -> None:
        """Let other batches into the output directory (the lock is also released when the process ends). A run
        that wrote no result there (it failed as a whole: no worker could run it, a full disk) takes away the lock,
        manifest and folders it made, so that it leaves the file system as it found it."""
        if self.lock_fd is not None:
            os.close(self.lock_fd)
            self.lock_fd = None
        if not self.out_dir.is_dir() or any(p.name not in (BATCH_LOCK, BATCH_MANIFEST) for p in self.out_dir.iterdir()):
            return
        for path in reversed(self.created):  # the files, then the folders, innermost first
            try:
                path.rmdir() if path.is_dir() else path.unlink()
            except OSError:  # someone else's file or folder appeared meanwhile: leave it
                return
        self.created = []

    def ordered(self, rows: Mapping[str, dict]) -> list[dict]:
        """``rows`` (keyed by bag name) in the order of the bags."""
        return [rows[name] for _, name in self.bags if name in rows]


def _json_settings(params: Mapping[str, Any]) -> dict:
    """The command's parameters as plain JSON data (tuples become lists), for the completion marker."""
    return json.loads(json.dumps(dict(params), sort_keys=True, default=str))


def check_out_dir(out_dir: Path, command: str) -> None:
    """Refuse an output directory that is a file, another command's batch, or someone's fleet table."""
    if out_dir.exists() and not out_dir.is_dir():
        raise BagtoolsError("is not a directory", out_dir)
    manifest = out_dir / BATCH_MANIFEST
    if manifest.is_file():
        try:
            owner = json.loads(manifest.read_text()).get("command")
        except (OSError, ValueError, AttributeError) as err:
            raise BagtoolsError(f"unreadable batch manifest ({err}); remove it or use another --out", manifest) from err
        if owner != command:
            raise BagtoolsError(f"holds a batch of 'bagtools {owner}'; use another --out for {command}", out_dir)
    elif out_dir.is_dir():
        foreign = sorted(name for name in RESERVED_NAMES if (out_dir / name).exists())
        if foreign:
            raise BagtoolsError(f"holds {', '.join(foreign)} that bagtools batch did not write; use another --out",
                                out_dir)


def lock_out_dir(out_dir: Path) -> tuple[int, list[Path]]:
    """Create ``out_dir`` if needed and hold its batch lock (``BATCH_LOCK``) for as long as the returned file
    descriptor is open (the process's life: the kernel releases it however the process ends); also returns the
    folders and the lock file this created, outermost first. A second batch into the same directory at once is
    refused (BagtoolsError naming the first's pid): the two would write the same bags' directories."""
    created = [p for p in reversed([out_dir, *out_dir.parents]) if not p.exists()]
    out_dir.mkdir(parents=True, exist_ok=True)
    if not (out_dir / BATCH_LOCK).exists():
        created.append(out_dir / BATCH_LOCK)
    fd = os.open(out_dir / BATCH_LOCK, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        holder = os.pread(fd, 64, 0).decode(errors="replace").strip() or "unknown"
        os.close(fd)
        raise BagtoolsError(f"another batch (pid {holder}) is writing into this directory now; wait for it to end, "
                            "or use another --out", out_dir) from None
    mine = f"{os.getpid()}\n".encode()
    if os.pread(fd, 64, 0) != mine:  # the holder's pid, for the message of a batch refused meanwhile
        os.ftruncate(fd, 0)
        os.pwrite(fd, mine, 0)
    return fd, created


def claim_out_dir(out_dir: Path, command: str) -> Path | None:
    """Create the output directory and its manifest (once; atomically); the manifest's path when this wrote it."""
    from bagtools.outputs import write_text_atomic

    if (out_dir / BATCH_MANIFEST).is_file():
        return None
    write_text_atomic(out_dir / BATCH_MANIFEST, json.dumps({"command": command}) + "\n", force=True)
    return out_dir / BATCH_MANIFEST


def plan_batch(command: str, bag_args: Sequence[str], out_dir: str | Path, params: Mapping[str, Any], force: bool,
               available: set[str] | None = None) -> BatchPlan:
    """Check the arguments and decide what each bag needs; raises BagtoolsError for a bad argument.

    ``params``: the command's parsed parameters without ``bag``, ``out_dir``
    and ``force`` (see :class:`~bagtools.batch.jobs.Job`). ``available``: the
    commands the CLI has (a job whose command is not there cannot run).
    """
    job = get_job(command, available)
    options = job.options(params)  # the command's own checks, before any work
    out_dir = Path(out_dir).absolute()
    check_out_dir(out_dir, command)
    bags = find_bags(bag_args, skip=[out_dir])
    refuse_input_overlap(out_dir, bags)  # results written into a bag, or bags inside the results, change the bags
    names = output_names(bags)
    settings = _json_settings({k: v for k, v in params.items() if k not in job.ignored})
    plan = BatchPlan(command, job, out_dir, force, list(zip(bags, names)))
    plan.lock_fd, plan.created = lock_out_dir(out_dir)  # before reading what earlier runs left: no other batch
    # changes it now
    for bag, name in plan.bags:
        task = BagTask(command, str(bag), name, str(out_dir), options, settings, force)
        marker = read_marker(task.bag_dir)
        try:
            check_owner(task, marker)
        except ForeignOutputError as err:
            row = new_row(task, FAILED, str(err))
            plan.decided[name] = row | {c.name: None for c in job.columns}
            continue
        done = None if force else completed_row(task, marker)
        if done is not None:
            plan.decided[name] = {k: done.get(k) for k in row_columns(job)}
        else:
            plan.tasks.append(task)
    return plan


def row_columns(job: Job) -> list[str]:
    """The fleet table's columns for ``job``: the common ones, then the command's."""
    return [*COMMON_COLUMNS, *(c.name for c in job.columns)]
