"""Set-up of the embedded cluster's worker processes, run by Dask as a preload (``dask_setup``).

Ctrl-C in a terminal reaches every process of the foreground group, the
workers too. The workers ignore it: the command itself cancels the tasks and
stops the cluster, so a worker neither prints a traceback nor dies on its own
first (outputs are atomic, so a bag stopped in the middle leaves nothing).
A worker still starting (importing Dask) cannot ignore it yet, so the cluster
is started with SIGINT ignored in the command too (:func:`sigint_ignored`): a
spawned process inherits an ignored signal across exec. A Ctrl-C in that
second or so is lost; the next one ends the run cleanly.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any


def dask_setup(worker: Any) -> None:
    """Ignore SIGINT in this worker process (the batch's client handles it)."""
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)


@contextmanager
def sigint_ignored() -> Iterator[None]:
    """Ignore SIGINT while the block runs (processes spawned meanwhile keep ignoring it), then restore the handler.

    Only the main thread may change a signal's handler; elsewhere this does nothing.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
