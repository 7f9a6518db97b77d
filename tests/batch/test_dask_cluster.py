"""``bagtools batch --scheduler`` on a real cluster: a ``dask scheduler`` and two ``dask worker`` processes on 127.0.0.1.

One worker is killed (SIGKILL) while it runs a bag; the scheduler gives the
bag to the other worker and the batch still completes every bag.
"""

from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from bagtools.batch.task import MARKER
from bagtools.cli import main
from tests.batch.conftest import Fleet

REPO = Path(__file__).resolve().parents[2]


def _dask(*args: str, log: Path) -> subprocess.Popen:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")])}
    return subprocess.Popen([sys.executable, "-m", "dask", *args], env=env, cwd=REPO, stdout=log.open("wb"),
                            stderr=subprocess.STDOUT, start_new_session=True)


def _wait_for(predicate, timeout_s: float, what: str) -> None:
    deadline = time.monotonic() + timeout_s
    while not predicate():
        if time.monotonic() > deadline:
            raise TimeoutError(f"timed out waiting for {what}")
        time.sleep(0.05)


@pytest.fixture
def cluster(tmp_path: Path) -> Iterator[tuple[str, dict[str, subprocess.Popen]]]:
    """A scheduler on a free port of 127.0.0.1 and two single-threaded workers (no nanny: killing one ends it)."""
    from distributed import Client

    scheduler_file = tmp_path / "scheduler.json"
    procs = {"scheduler": _dask("scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
                                "--scheduler-file", str(scheduler_file), log=tmp_path / "scheduler.log")}
    try:
        _wait_for(scheduler_file.exists, 60, "the scheduler")
        address = json.loads(scheduler_file.read_text())["address"]
        for name in ("w1", "w2"):
            procs[name] = _dask("worker", address, "--name", name, "--nthreads", "1", "--no-nanny", "--host",
                                "127.0.0.1", "--no-dashboard", log=tmp_path / f"{name}.log")
        with Client(address, timeout="30s") as client:
            client.wait_for_workers(2, timeout=60)
        yield address, procs
    finally:  # throwaway processes without children (no nannies): no need to wait for a graceful close
        for proc in procs.values():
            if proc.poll() is None:
                proc.kill()
            proc.wait()


def _kill_worker_mid_task(address: str, procs: dict[str, subprocess.Popen], killed: list[str]) -> None:
    """Kill worker w1 as soon as the scheduler says it is running a bag; record that bag's task key."""
    from distributed import Client

    with Client(address, timeout="30s") as client:
        w1 = next(addr for addr, w in client.scheduler_info()["workers"].items() if w.get("name") == "w1")
        running: list = []

        def w1_busy() -> bool:
            running[:] = client.processing(workers=[w1]).get(w1, [])
            return bool(running)

        _wait_for(w1_busy, 120, "worker w1 to run a bag")
        procs["w1"].kill()
        procs["w1"].wait(timeout=20)
        killed.extend(running)


def test_a_killed_worker_does_not_stop_the_batch(fleet: Fleet, cluster, tmp_path: Path, capsys) -> None:
    address, procs = cluster
    out_dir = tmp_path / "out"
    killed: list[str] = []
    killer = threading.Thread(target=_kill_worker_mid_task, args=(address, procs, killed), daemon=True)
    killer.start()
    with pytest.raises(SystemExit) as exit_info:
        main(["batch", "ndt-odom", *map(str, fleet.good), "--out", str(out_dir), "--scheduler", address])
    killer.join(timeout=30)
    out, err = capsys.readouterr()
    assert exit_info.value.code == 0, err
    assert killed and procs["w1"].returncode == -signal.SIGKILL, "w1 must have been killed during a bag"
    assert all(key.startswith("bagtools-ndt-odom-") for key in killed)
    with (out_dir / "fleet.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert [r["status"] for r in rows] == ["ok"] * len(fleet.good)
    assert f"{len(fleet.good)} bags: {len(fleet.good)} ok" in out and "on the Dask cluster at" in err
    for r in rows:
        assert (out_dir / r["bag"] / MARKER).is_file() and (out_dir / r["bag"] / "trajectory.tum").is_file()
    assert not list(out_dir.rglob("*.tmp"))  # the killed bag's staging was swept when it was redone


@pytest.fixture
def nanny_cluster(tmp_path: Path) -> Iterator[str]:
    """A scheduler that gives up on a task after 2 worker deaths, and one single-threaded worker under a nanny
    (restarted when it dies) whose preload makes a bag named ``kills-its-worker`` end the worker process."""
    from distributed import Client

    scheduler_file = tmp_path / "scheduler.json"
    os.environ["DASK_DISTRIBUTED__SCHEDULER__ALLOWED_FAILURES"] = "1"
    try:
        procs = [_dask("scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
                       "--scheduler-file", str(scheduler_file), log=tmp_path / "scheduler.log")]
    finally:
        del os.environ["DASK_DISTRIBUTED__SCHEDULER__ALLOWED_FAILURES"]
    try:
        _wait_for(scheduler_file.exists, 60, "the scheduler")
        address = json.loads(scheduler_file.read_text())["address"]
        procs.append(_dask("worker", address, "--nthreads", "1", "--nworkers", "1", "--host", "127.0.0.1",
                           "--no-dashboard", "--preload", "tests.batch.killer_worker", log=tmp_path / "worker.log"))
        with Client(address, timeout="30s") as client:
            client.wait_for_workers(1, timeout=60)
        yield address
    finally:
        for proc in procs:  # the nanny has a child: end the whole process group
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()


def test_a_bag_that_kills_its_worker_fails_alone_and_the_bag_queued_beside_it_is_redone(
        fleet: Fleet, nanny_cluster: str, tmp_path: Path, capsys) -> None:
    import shutil

    killer = tmp_path / "bags" / "kills-its-worker"
    shutil.copytree(fleet.good[0], killer)
    (killer / "padding.bin").write_bytes(b"\0" * 10_000_000)  # the largest bag: it starts first, the other queues
    out_dir = tmp_path / "out"
    with pytest.raises(SystemExit) as exit_info:
        main(["batch", "grid", str(killer), str(fleet.good[2]), "--out", str(out_dir), "--scheduler", nanny_cluster,
              "--", "--no-mcap"])
    out, err = capsys.readouterr()
    assert exit_info.value.code == 1, err
    with (out_dir / "fleet.csv").open() as f:
        rows = {r["bag"]: r for r in csv.DictReader(f)}
    assert rows[fleet.good[2].name]["status"] == "ok", rows
    assert rows["kills-its-worker"]["status"] == "failed"
    assert "died each time it was tried, also with no other bag beside it" in rows["kills-its-worker"]["error"]
