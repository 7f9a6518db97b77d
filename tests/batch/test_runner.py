"""Dask's own failures as rows, and the size of the embedded cluster (no cluster started here)."""

from __future__ import annotations

import os

from distributed import KilledWorker

from bagtools.batch.runner import ClusterSpec, row_of_future
from bagtools.batch.task import FAILED, BagTask


class _Future:
    def __init__(self, status: str, result: object = None, exception: BaseException | None = None) -> None:
        self.status, self._result, self._exception = status, result, exception

    def result(self) -> object:
        return self._result

    def exception(self) -> BaseException | None:
        return self._exception


TASK = BagTask("grid", "/data/run1", "run1", "/out", None, {}, False)


def test_a_finished_future_gives_the_tasks_row() -> None:
    row = {"bag": "run1", "status": "ok"}
    assert row_of_future(_Future("finished", row), TASK) is row


def test_a_bag_that_killed_every_worker_is_a_failed_row_that_says_so() -> None:
    row = row_of_future(_Future("error", exception=KilledWorker("bagtools-grid-run1-x", "tcp://w:1", 3)), TASK)
    assert row["status"] == FAILED and row["bag"] == "run1"
    assert row["error"] == ("/data/run1: the worker running it died each time it was tried, also with no other bag "
                            "beside it (killed, out of memory, "
                            "or a crash in native code)")


def test_other_dask_failures_are_internal_errors_on_one_line() -> None:
    row = row_of_future(_Future("error", exception=RuntimeError("lost\nconnection")), TASK)
    assert row["status"] == FAILED and row["error"] == "internal error: RuntimeError: lost connection"
    assert row_of_future(_Future("cancelled"), TASK)["error"] == "internal error: Dask cancelled the task"


def test_the_embedded_cluster_has_one_worker_per_usable_core_unless_told() -> None:
    assert ClusterSpec().local_workers() == len(os.sched_getaffinity(0))
    assert ClusterSpec(workers=5).local_workers() == 5


def test_a_silent_listener_is_not_taken_for_a_scheduler() -> None:
    """Something that accepts connections and never speaks (not Dask) made the Client wait for ever, whatever its
    timeout; a port where nothing listens is refused at once."""
    import socket
    import threading

    import pytest

    from bagtools.batch.runner import check_speaks_dask
    from bagtools.errors import BagtoolsError

    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(1)
    port = server.getsockname()[1]
    held = []
    threading.Thread(target=lambda: held.append(server.accept()), daemon=True).start()
    try:
        with pytest.raises(BagtoolsError, match="says nothing within 0.5 s"):
            check_speaks_dask(f"tcp://127.0.0.1:{port}", wait_s=0.5)
    finally:
        server.close()
    with pytest.raises(BagtoolsError, match="cannot reach the Dask scheduler"):
        check_speaks_dask(f"tcp://127.0.0.1:{port}", wait_s=0.5)


def test_no_start_line_before_the_workers_are_found_able(monkeypatch, tmp_path) -> None:
    """The batch said 'N bags to run on the Dask cluster' and then failed its worker check: the line now comes
    only once every worker can run the batch."""
    from contextlib import contextmanager

    import pytest

    from bagtools.batch.plan import BatchPlan
    from bagtools.batch.runner import BatchRun
    from bagtools.errors import BagtoolsError

    class _Client:
        def nthreads(self) -> dict:
            return {"tcp://w:1": 1}

        def run(self, fn, *args):
            return {"tcp://w:1": "cannot see /data"}

    @contextmanager
    def fake_client(self):
        yield _Client()

    monkeypatch.setattr(BatchRun, "_client", fake_client)
    plan = BatchPlan("grid", None, tmp_path / "out", False, [(tmp_path / "run1.mcap", "run1")], tasks=[TASK])
    said: list[str] = []
    with pytest.raises(BagtoolsError, match="cannot see /data"):
        BatchRun(plan, ClusterSpec(scheduler="tcp://head:8786"), said.append).run()
    assert said == [] and not (tmp_path / "out").exists()


def test_with_no_worker_left_the_waiting_bags_fail_and_the_batch_ends(monkeypatch, tmp_path) -> None:
    """Every worker gone (killed for memory, none taking its place) while bags wait: after WORKERLESS_S they are
    failed rows that say so, and the batch ends (#42: it waited forever). A cluster of no worker stands in."""
    from contextlib import contextmanager

    from distributed import Client, LocalCluster

    from bagtools.batch import runner
    from bagtools.batch.plan import BatchPlan
    from bagtools.batch.runner import BatchRun

    @contextmanager
    def workerless(self):
        with LocalCluster(n_workers=0, processes=False, dashboard_address=":0") as cluster, Client(cluster) as client:
            yield client

    monkeypatch.setattr(BatchRun, "_client", workerless)
    monkeypatch.setattr(runner, "WORKERLESS_S", 1.0)
    monkeypatch.setattr(runner, "WATCH_S", 0.2)
    tasks = [BagTask("info", f"/data/run{k}", f"run{k}", str(tmp_path / "out"), None, {}, False) for k in (1, 2)]
    plan = BatchPlan("info", None, tmp_path / "out", False, [(tmp_path / t.name, t.name) for t in tasks], tasks=tasks)
    monkeypatch.setattr("bagtools.batch.runner.row_columns", lambda job: ["bag", "status", "error"])
    rows = BatchRun(plan, ClusterSpec()).run()
    assert [r["status"] for r in rows] == [FAILED, FAILED]
    assert all("no Dask worker was left to run it" in r["error"] for r in rows), rows
