"""Messages held back until tf is known, in bound memory.

map-cloud reads a bag once: the clouds (cut and sampled, in their sensor
frame) come in with the tf messages, and are placed once all of tf is read
(repaired as a whole, as tf2 would see it at the end of the bag). What waits
is kept in memory up to a budget; beyond it, batches go to a temporary
directory (``bagtools-held-<pid>-*``) and are read back in order. A run
killed with SIGKILL cannot remove its directory: the next run that spills
removes every such directory whose process is gone.
"""

from __future__ import annotations

import os
import pickle
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from bagtools.cloud.accumulator import MapCloud
from bagtools.errors import BagtoolsError

HELD_PREFIX = "bagtools-held-"

#: Bytes of held points kept in memory; more are written to a temporary directory in batches of this size.
MEMORY_BUDGET_BYTES = 64 * 1024 * 1024


class HeldCloud(NamedTuple):
    """One message's points as they will go into the map: ``cloud`` in sensor frame ``frame_id`` at header
    ``stamp_ns`` (bag time ``log_time_ns``); ``scan`` the LaserScan it came from, when kept."""

    stamp_ns: int
    log_time_ns: int
    frame_id: str
    cloud: MapCloud
    scan: Any = None


def _nbytes(held: HeldCloud) -> int:
    arrays = (held.cloud.points, held.cloud.intensity, held.cloud.rgb)
    scan_bytes = held.scan.ranges_m.nbytes if held.scan is not None else 0
    return sum(a.nbytes for a in arrays if isinstance(a, np.ndarray)) + scan_bytes + 200


class HeldClouds:
    """Clouds in bag order, in memory up to ``budget_bytes`` and on disk beyond; iterate once, then close."""

    def __init__(self, budget_bytes: int = MEMORY_BUDGET_BYTES) -> None:
        self.budget_bytes = budget_bytes
        self._batch: list[HeldCloud] = []
        self._batch_bytes = 0
        self._spilled: list[Path] = []
        self._dir: tempfile.TemporaryDirectory | None = None
        self.count = 0
        self.spilled_batches = 0  # batches that went to disk

    def add(self, held: HeldCloud) -> None:
        self._batch.append(held)
        self._batch_bytes += _nbytes(held)
        self.count += 1
        if self._batch_bytes > self.budget_bytes:
            self._spill()

    def _spill(self) -> None:
        if self._dir is None:
            remove_orphans()
            self._dir = tempfile.TemporaryDirectory(prefix=f"{HELD_PREFIX}{os.getpid()}-")
        path = Path(self._dir.name) / f"{len(self._spilled):06d}.pickle"
        try:
            with path.open("wb") as f:
                pickle.dump(self._batch, f, protocol=pickle.HIGHEST_PROTOCOL)
        except OSError as err:  # a full temporary directory is the temporary directory's problem, not the bag's
            raise BagtoolsError(f"cannot hold clouds there while tf is read ({err.strerror or err}); set TMPDIR to a "
                                "directory with room", self._dir.name) from err
        self._spilled.append(path)
        self.spilled_batches += 1
        self._batch, self._batch_bytes = [], 0

    def __iter__(self) -> Iterator[HeldCloud]:
        for path in self._spilled:
            with path.open("rb") as f:
                batch = pickle.load(f)  # our own file, written above in this run
            path.unlink()
            yield from batch
        yield from self._batch

    def close(self) -> None:
        """Remove the temporary directory (also when iteration stopped early)."""
        if self._dir is not None:
            self._dir.cleanup()
            self._dir = None
        self._batch, self._spilled = [], []


def remove_orphans(directory: str | None = None) -> list[Path]:
    """Remove the spill directories of map-cloud runs whose process is gone (killed by SIGKILL, which no cleanup
    survives) from ``directory`` (default: the temporary directory); returns them."""
    removed = []
    for path in Path(directory or tempfile.gettempdir()).glob(f"{HELD_PREFIX}*-*"):
        pid_text = path.name[len(HELD_PREFIX):].split("-", 1)[0]
        if not pid_text.isdigit() or _alive(int(pid_text)) or not path.is_dir():
            continue
        shutil.rmtree(path, ignore_errors=True)
        removed.append(path)
    return removed


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's process
        return True
    return True
