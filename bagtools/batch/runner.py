"""Running a batch on Dask (``dask.distributed``): an embedded LocalCluster, or an existing cluster.

Embedded (the default): a ``distributed.LocalCluster`` of one single-threaded
worker process per core (``threads_per_worker=1``; Dask's nannies set
OMP_NUM_THREADS=1 and friends in each worker), started and stopped here. With
a scheduler address the same tasks go to an existing cluster (``dask
scheduler`` / ``dask worker``, dask-jobqueue, dask-kubernetes); its workers
must import the same bagtools and see the bags and the output directory at
the same paths, which :meth:`BatchRun.run` checks on every worker first.

Each bag is one task, :func:`bagtools.batch.task.run_task`, largest bag first
(the long ones do not end up last, alone). A problem with a bag is a row, not
an exception; a worker that dies mid-task (killed, out of memory) has its task
run again on another worker by the scheduler, up to Dask's
``distributed.scheduler.allowed-failures`` times. Dask blames every task a
dying worker held, the bags queued behind the one running too, so a bag that
Dask gives up on (``KilledWorker``) is run once more alone, after the rest:
it is a failed row only when it kills the workers it runs on by itself, and an
innocent bag that was merely queued beside it is redone. ``retries`` covers
the rest of Dask's own failures (a task that could not be sent or unpacked).
"""

from __future__ import annotations

import importlib.util
import logging
import os
import threading
import time
import uuid
from collections.abc import Callable, Iterator
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from bagtools.batch.fleet import preload_fleet_writers
from bagtools.batch.plan import BatchPlan, claim_out_dir, row_columns
from bagtools.batch.task import (
    FAILED, SKIPPED, BagTask, completed_row, new_row, one_line, read_marker, run_task,
)
from bagtools.batch.worker import sigint_ignored
from bagtools.errors import BagtoolsError
from bagtools.progress import progress_bar

#: How long a scheduler may take to send its handshake after a connection, seconds.
SCHEDULER_HANDSHAKE_S = 10.0
#: Times a task is resubmitted after a Dask failure that is not the bag's (the bag's own errors are rows).
TASK_RETRIES = 2


@dataclass(frozen=True)
class ClusterSpec:
    """Where to run: ``scheduler`` (an address like tcp://host:8786) or an embedded cluster of ``workers`` processes.

    ``workers`` None: one per core this process may use.
    """

    workers: int | None = None
    scheduler: str | None = None

    def local_workers(self) -> int:
        """Worker processes of the embedded cluster."""
        if self.workers is not None:
            return self.workers
        try:
            return len(os.sched_getaffinity(0))
        except AttributeError:  # not Linux
            return os.cpu_count() or 1


def check_speaks_dask(address: str, wait_s: float | None = None) -> None:
    """Raise :class:`BagtoolsError` unless a ``tcp://`` ``address`` answers as a Dask scheduler does: its
    handshake arrives as soon as one connects. Something else listening there (silent) made the Client wait for
    ever, whatever its timeout. Other schemes (tls://, inproc://) are left to Dask."""
    import socket
    from urllib.parse import urlsplit

    if not address.startswith("tcp://"):
        return
    wait_s = SCHEDULER_HANDSHAKE_S if wait_s is None else wait_s
    parts = urlsplit(address)
    try:
        with socket.create_connection((parts.hostname, parts.port or 8786), timeout=wait_s) as sock:
            sock.settimeout(wait_s)
            first = sock.recv(1)
    except TimeoutError as err:
        raise BagtoolsError(f"something listens there but says nothing within {wait_s:g} s, as no Dask scheduler "
                            "does: is this the scheduler's address (dask scheduler prints it)?", address) from err
    except (OSError, ValueError) as err:
        raise BagtoolsError(f"cannot reach the Dask scheduler: {one_line(str(err), 200)}", address) from err
    if not first:
        raise BagtoolsError("the connection was closed at once, as no Dask scheduler does: is this the "
                            "scheduler's address?", address)


def _bag_bytes(bag: str) -> int:
    """Size of a bag on disk (all files of a rosbag2 directory), bytes; 0 when unreadable."""
    path = Path(bag)
    try:
        if path.is_dir():
            return sum(p.stat().st_size for p in path.iterdir() if p.is_file())
        return path.stat().st_size
    except OSError:
        return 0


def _worker_ready(command: str, version: str, paths: list[str]) -> str | None:
    """On each worker: None when it can run this batch, else what is wrong (imports the command's modules once)."""
    import bagtools
    from bagtools.batch.jobs import JOBS

    if bagtools.__version__ != version:
        return f"has bagtools {bagtools.__version__}, this command is {version}"
    missing = [p for p in paths if not os.path.exists(p)]
    if missing:
        return f"cannot see {missing[0]}"
    JOBS[command]  # noqa: B018 - the registry imports nothing heavy; the first task does, once per worker
    return None


def _scheduler_has_dashboard() -> bool:
    return importlib.util.find_spec("bokeh") is not None


class BatchRun:
    """Run a :class:`BatchPlan` on Dask and collect one row per bag.

    ``notify`` receives one-line messages for the user (the cluster, the
    dashboard address). :attr:`rows` fills in as bags finish, so after an
    interruption it holds what was done.
    """

    def __init__(self, plan: BatchPlan, cluster: ClusterSpec, notify: Callable[[str], None] = lambda text: None) -> None:
        self.plan = plan
        self.cluster = cluster
        self.notify = notify
        self.rows: dict[str, dict] = dict(plan.decided)

    def run(self) -> list[dict]:
        """Run every task; return the rows in bag order. KeyboardInterrupt cancels what is left and re-raises."""
        if self.plan.tasks:
            with self._client() as client:
                self._check_workers(client)
                self._announce(client)  # only once the workers can run the batch: no start line before an error
                manifest = claim_out_dir(self.plan.out_dir, self.plan.command)
                if manifest is not None:
                    self.plan.created.append(manifest)
                futures = self._submit(client, self.plan.tasks)
                try:
                    blamed = self._collect(client, futures, len(client.nthreads()))
                    for task in blamed:  # alone now: a bag that kills its worker again is the culprit
                        futures = self._submit(client, [task])
                        self._collect(client, futures, len(client.nthreads()), alone=True)
                except BaseException:
                    client.cancel(list(futures), force=True)
                    raise
        return self.plan.ordered(self.rows)

    def done_count(self) -> int:
        """Bags of this run's tasks whose outputs are complete now (e.g. after an interruption)."""
        return sum(completed_row(t, read_marker(t.bag_dir)) is not None for t in self.plan.tasks)

    # -- the cluster ------------------------------------------------------------

    @contextmanager
    def _client(self) -> Iterator[Any]:
        from distributed import Client

        if self.cluster.scheduler:
            check_speaks_dask(self.cluster.scheduler)
            try:
                client = Client(self.cluster.scheduler, timeout="20s")
            except (OSError, TimeoutError, ValueError) as err:
                raise BagtoolsError(f"cannot reach the Dask scheduler: {one_line(str(err), 200)}",
                                    self.cluster.scheduler) from err
            try:
                if not client.nthreads():
                    self.notify(f"waiting for a Dask worker to join {self.cluster.scheduler} ...")
                    client.wait_for_workers(1)
                yield client
            finally:
                client.close()
            return
        from distributed import LocalCluster

        import dask

        n = min(self.cluster.local_workers(), len(self.plan.tasks))
        bokeh = importlib.util.find_spec("bokeh") is not None
        # Worker processes stopped by Ctrl-C leave multiprocessing semaphores that Python's resource tracker (a
        # process of its own, started with the cluster) cleans up, warning of each as "leaked" as the batch ends:
        # noise after the batch's own one line. The tracker reads its warning filters from the environment.
        quiet = "ignore:resource_tracker:UserWarning"
        if quiet not in os.environ.get("PYTHONWARNINGS", ""):
            os.environ["PYTHONWARNINGS"] = ",".join(filter(None, [os.environ.get("PYTHONWARNINGS"), quiet]))
        with ExitStack() as stack:
            # Dask samples every task's stack for the dashboard's profile page: 5 % of a bag's time, so only with one.
            stack.enter_context(dask.config.set({"distributed.worker.profile.enabled": bokeh}))
            with sigint_ignored():
                # CRITICAL: a worker whose scheduler went first (Ctrl-C) logs its failed heartbeat as an ERROR
                # with a traceback; a bag's own failure is its row, and a lost worker reaches the client anyway.
                cluster = stack.enter_context(LocalCluster(
                    n_workers=n, threads_per_worker=1, processes=True, silence_logs=logging.CRITICAL,
                    dashboard_address=":8787" if bokeh else ":0", preload=["bagtools.batch.worker"]))
                client = stack.enter_context(Client(cluster))
            yield client

    def _announce(self, client: Any) -> None:
        """Say where the bags run, and the dashboard's address when there is one."""
        n = len(client.nthreads())
        if self.cluster.scheduler:
            self.notify(f"{len(self.plan.tasks)} bags to run on the Dask cluster at {self.cluster.scheduler} "
                        f"({n} workers now)")
            self._announce_dashboard(client, remote=True)
        else:
            self.notify(f"{len(self.plan.tasks)} bags to run on {n} local worker process{'es' if n > 1 else ''}")
            if importlib.util.find_spec("bokeh") is not None:
                self._announce_dashboard(client, remote=False)

    def _announce_dashboard(self, client: Any, remote: bool) -> None:
        """Print the dashboard address when the scheduler serves one (it needs bokeh)."""
        try:
            if remote and not client.run_on_scheduler(_scheduler_has_dashboard):
                return
        except Exception:  # a scheduler that refuses to run code: say nothing
            return
        link = client.dashboard_link
        if link:
            self.notify(f"Dask dashboard: {link}")

    def _check_workers(self, client: Any) -> None:
        import bagtools

        out = self.plan.out_dir  # it may not exist yet: its nearest existing folder must be visible
        while not out.exists() and out.parent != out:
            out = out.parent
        paths = [self.plan.tasks[0].bag, str(out)]
        try:
            problems = client.run(_worker_ready, self.plan.command, bagtools.__version__, paths)
        except Exception as err:  # e.g. a worker without bagtools cannot even unpack the check
            raise BagtoolsError(f"the Dask workers cannot run bagtools ({type(err).__name__}: "
                                f"{one_line(str(err), 200)}); they need the same Python environment",
                                self.cluster.scheduler or "workers") from err
        bad = {worker: why for worker, why in problems.items() if why}
        if bad:
            worker, why = next(iter(bad.items()))
            raise BagtoolsError(f"Dask worker {worker} {why}: every worker needs the same bagtools and the bags and "
                                f"--out at the same paths", self.cluster.scheduler or "workers")

    # -- the tasks --------------------------------------------------------------

    def _submit(self, client: Any, tasks: list[BagTask]) -> dict[Any, BagTask]:
        """Submit ``tasks``, largest bag first; returns future -> task."""
        batch_id = uuid.uuid4().hex[:8]
        tasks = sorted(tasks, key=lambda t: _bag_bytes(t.bag), reverse=True)
        futures = {}
        for rank, task in enumerate(tasks):
            future = client.submit(run_task, task, key=f"bagtools-{task.command}-{task.name}-{batch_id}",
                                   retries=TASK_RETRIES, priority=len(tasks) - rank, pure=False)
            futures[future] = task
        return futures

    def _collect(self, client: Any, futures: dict[Any, BagTask], workers: int, alone: bool = False) -> list[BagTask]:
        """Rows of the finished ``futures`` as they come, with a progress bar; ``workers``: how many run them.

        Returns the tasks Dask gave up on because their workers died (``KilledWorker``), which may be
        innocent bags queued beside the culprit; their rows are written only when ``alone`` (a task
        run by itself, whose worker deaths are its own). When no worker has been left for ``WORKERLESS_S``
        (killed for memory and not replaced), the tasks still waiting are failed rows: the batch ends.
        """
        from distributed import KilledWorker

        columns = row_columns(self.plan.job)
        skipped = sum(row["status"] == SKIPPED for row in self.rows.values())
        remaining = len(futures)
        blamed: list[BagTask] = []
        with progress_bar(total=self.plan.total, desc=f"batch {self.plan.command}", unit="bag") as bar:
            bar.update(len(self.rows))
            for future, lost in _as_finished(client, list(futures)):
                remaining -= 1
                if remaining == workers - 1 and not alone:  # a worker is idle for good: preload the fleet writers
                    threading.Thread(target=preload_fleet_writers, name="bagtools-preload", daemon=True).start()
                task = futures[future]
                if lost:
                    row = new_row(task, FAILED, f"{task.bag}: no Dask worker was left to run it (the workers died, "
                                                "killed for memory or crashed, and none took their place)")
                    self.rows[task.name] = {k: row.get(k) for k in columns}
                    bar.update(1)
                    continue
                if not alone and future.status == "error" and isinstance(future.exception(), KilledWorker):
                    blamed.append(task)
                    continue
                row = row_of_future(future, task)
                self.rows[task.name] = {k: row.get(k) for k in columns}
                bar.update(1)
                failed = sum(r["status"] == FAILED for r in self.rows.values())
                bar.set_postfix(failed=failed, skipped=skipped, refresh=False)
        return blamed


#: How long a batch waits with tasks pending and no worker at all before it fails those tasks (s); and how often it
#: looks (s). A worker killed for memory is replaced by its nanny within seconds, when it is.
WORKERLESS_S = 60.0
WATCH_S = 5.0


def _as_finished(client: Any, futures: list[Any]) -> Iterator[tuple[Any, bool]]:
    """(future, lost) as each of ``futures`` finishes, lost False; once no worker has been left for WORKERLESS_S
    while some are pending, those are cancelled and given as lost (True)."""
    from distributed import wait

    pending = set(futures)
    workerless_since: float | None = None
    while pending:
        try:
            done, pending = wait(pending, timeout=WATCH_S, return_when="FIRST_COMPLETED")
        except TimeoutError:
            done = set()
        for future in done:
            yield future, False
        if done or client.nthreads():
            workerless_since = None
            continue
        workerless_since = workerless_since if workerless_since is not None else time.monotonic()
        if time.monotonic() - workerless_since >= WORKERLESS_S:
            client.cancel(list(pending), force=True)
            for future in list(pending):
                yield future, True
            return


def row_of_future(future: Any, task: BagTask) -> dict:
    """The row of a finished Dask future of ``task``; a failure of Dask itself is a failed row.

    The task never raises for its bag, so an error here is Dask's: the bag
    killed every worker it ran on (``KilledWorker``), or something internal.
    """
    from distributed import KilledWorker

    if future.status == "finished":
        return future.result()
    if future.status == "cancelled":
        return new_row(task, FAILED, "internal error: Dask cancelled the task")
    exc = future.exception()
    if isinstance(exc, KilledWorker):
        return new_row(task, FAILED, f"{task.bag}: the worker running it died each time it was tried, "
                                     "also with no other bag beside it (killed, out of memory, or a crash in "
                                     "native code)")
    return new_row(task, FAILED, one_line(f"internal error: {type(exc).__name__}: {exc}"))


def run_batch(plan: BatchPlan, cluster: ClusterSpec, notify: Callable[[str], None] = lambda text: None) -> list[dict]:
    """Run ``plan`` (see :class:`BatchRun`) and return one row per bag, in bag order."""
    return BatchRun(plan, cluster, notify).run()
