"""The embedded cluster's worker processes never see Ctrl-C: ignored from their start, and by their preload."""

from __future__ import annotations

import multiprocessing
import signal

from bagtools.batch.worker import sigint_ignored


def _report_sigint(queue: multiprocessing.Queue) -> None:
    queue.put(signal.getsignal(signal.SIGINT) == signal.SIG_IGN)


def _spawned_child_ignores_sigint() -> bool:
    ctx = multiprocessing.get_context("spawn")  # Dask's way of starting a worker: fork and exec a new Python
    queue = ctx.Queue()
    child = ctx.Process(target=_report_sigint, args=(queue,))
    child.start()
    ignores = queue.get(timeout=60)
    child.join(timeout=60)
    return ignores


def test_a_process_spawned_while_sigint_is_ignored_ignores_it_from_its_start() -> None:
    before = signal.getsignal(signal.SIGINT)
    with sigint_ignored():
        assert _spawned_child_ignores_sigint()
    assert signal.getsignal(signal.SIGINT) is before  # the command's own Ctrl-C handling is back
    assert not _spawned_child_ignores_sigint()  # the control: a plain spawn gets Python's KeyboardInterrupt
