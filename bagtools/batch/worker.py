"""Set-up of the embedded cluster's worker processes, run by Dask as a preload (``dask_setup``).

Ctrl-C in a terminal reaches every process of the foreground group, the
workers too. The workers ignore it: the command itself cancels the tasks and
stops the cluster, so a worker neither prints a traceback nor dies on its own
first (outputs are atomic, so a bag stopped in the middle leaves nothing).
"""

from __future__ import annotations

import signal
import threading
from typing import Any


def dask_setup(worker: Any) -> None:
    """Ignore SIGINT in this worker process (the batch's client handles it)."""
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)
