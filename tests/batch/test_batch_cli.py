"""``bagtools batch`` end to end on an embedded LocalCluster of 2 workers: rows, exit status, resume, --force, Ctrl-C."""

from __future__ import annotations

import csv
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pyarrow.parquet as pq
import pytest

from bagtools.batch.bags import BATCH_LOCK, BATCH_MANIFEST
from bagtools.batch.jobs import JOBS
from bagtools.batch.task import MARKER
from bagtools.cli import main
from bagtools.commands.grid import GRID_MAP_FILES
from tests.batch.conftest import Fleet, tree_state

REPO = Path(__file__).resolve().parents[2]
GRID_FILES = sorted([*GRID_MAP_FILES, MARKER])


def _batch(argv: list[str], capsys) -> tuple[int, str, str]:
    with pytest.raises(SystemExit) as exit_info:
        main(["batch", *argv])
    out = capsys.readouterr()
    return exit_info.value.code, out.out, out.err


def _rows(out_dir: Path) -> list[dict]:
    with (out_dir / "fleet.csv").open() as f:
        return list(csv.DictReader(f))


def test_help_has_an_example(capsys) -> None:
    code, out, _ = _batch(["--help"], capsys)
    assert code == 0 and "Example:" in out and "bagtools batch ndt-odom /data/2026-11-22/ --out fleet/ndt" in out
    assert "--scheduler" in out and "--workers" in out


def test_a_command_batch_cannot_run_is_the_command_lines_fault_not_the_bags(fleet: Fleet, tmp_path: Path,
                                                                            capsys) -> None:
    code, _, err = _batch(["export", str(fleet.good[0]), "--out", str(tmp_path / "out"), "--", "/scan"], capsys)
    assert code == 2 and err.strip() == ("bagtools: invalid value for COMMAND: 'export' is not a command batch can "
                                         "run (choose from grid, info, localize, map-cloud, ndt-odom, slam) (see 'bagtools "
                                         "batch --help')"), err


@pytest.mark.parametrize("args, problem", [
    (["tf", "{bag}"], "'tf' is not a command batch can run (choose from grid, info, localize, map-cloud, ndt-odom, slam)"),
    (["grid", "{bag}", "--", "--resolution", "abc"], "'abc' is not a valid float (see 'bagtools grid --help')"),
    (["grid", "{bag}", "--", "--resolution", "0"], "--resolution must be between 0.1 and 1000"),
    (["ndt-odom", "{bag}", "--", "--init", "guess"], "invalid value for '--init'"),
    (["grid", "{bag}", "--", "--out", "elsewhere"], "--out is batch's own option: give it before '--'"),
    (["grid", "{bag}", "--", "--force"], "--force is batch's own option"),
    (["grid", "{bag}", "--", "second.mcap"], "got unexpected extra argument (second.mcap)"),
    (["grid", "{root}/missing"], "missing: no such file or directory"),
    (["grid", "{root}/nothing*"], "matches no file or directory"),
    (["grid", "{bag}", "--workers", "0"], "invalid value for '--workers'"),
    (["grid", "{bag}", "--workers", "2", "--scheduler", "tcp://127.0.0.1:1"], "--workers sizes the embedded cluster"),
    (["grid", "{bag}", "--scheduler", ""], "--scheduler is empty"),
    (["grid", "{bag}", "--", "--poses", "/missing.tum"], "/missing.tum: no such trajectory file"),
    (["slam", "{bag}", "--", "--relations", "/missing.relations"], "/missing.relations: cannot read the relations"),
    (["grid", "{bag}", "--scheduler", "  "], "--scheduler is empty"),
])
def test_bad_arguments_are_one_line_and_exit_2_before_any_work(args: list[str], problem: str, fleet: Fleet,
                                                               tmp_path: Path, capsys) -> None:
    out_dir = tmp_path / "out"
    argv = [a.format(bag=fleet.good[0], root=fleet.root) for a in args]
    cut = argv.index("--") if "--" in argv else len(argv)
    code, _, err = _batch([*argv[:cut], "--out", str(out_dir), *argv[cut:]], capsys)
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1 and lines[0].startswith("bagtools: "), err
    assert problem in lines[0]
    assert not out_dir.exists()


def test_an_output_directory_of_another_command_or_with_someones_table_is_refused(fleet: Fleet, tmp_path: Path,
                                                                                   capsys) -> None:
    grid_batch = tmp_path / "grid"
    grid_batch.mkdir()
    (grid_batch / BATCH_MANIFEST).write_text(json.dumps({"command": "grid"}))
    code, _, err = _batch(["ndt-odom", str(fleet.good[0]), "--out", str(grid_batch)], capsys)
    assert code == 2 and "holds a batch of 'bagtools grid'; use another --out for ndt-odom" in err
    theirs = tmp_path / "theirs"
    theirs.mkdir()
    (theirs / "fleet.csv").write_text("their,table\n")
    code, _, err = _batch(["grid", str(fleet.good[0]), "--out", str(theirs), "--force"], capsys)
    assert code == 2 and "holds fleet.csv that bagtools batch did not write" in err
    assert (theirs / "fleet.csv").read_text() == "their,table\n"


def test_bad_bags_are_rows_a_rerun_skips_what_is_done_and_force_redoes_it(fleet: Fleet, tmp_path: Path,
                                                                            capsys) -> None:
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    (out_dir / "notes.txt").write_text("the user's own file")
    argv = ["grid", str(fleet.root), "--out", str(out_dir), "--workers", "2"]
    code, out, err = _batch(argv, capsys)

    assert code == 1, err
    assert "6 bags: 4 ok, 0 skipped (done before), 2 failed" in out
    rows = _rows(out_dir)
    assert [r["bag"] for r in rows] == ["a__run1", "b__run1", "corrupt", "no_scan", "run2", "run3"]
    assert [r["status"] for r in rows] == ["ok", "ok", "failed", "failed", "ok", "ok"]
    by_name = {r["bag"]: r for r in rows}
    assert by_name["corrupt"]["error"].startswith(f"{fleet.corrupt}: truncated MCAP")
    assert by_name["no_scan"]["error"].startswith(f"{fleet.no_scan}: no topic '/scan' in the bag")
    assert by_name["no_scan"]["messages"] == "20" and by_name["corrupt"]["messages"] == ""
    assert f"bagtools: corrupt: failed: {by_name['corrupt']['error']}" in err.splitlines()
    for r in rows:
        if r["status"] == "ok":
            assert r["error"] == "" and int(r["messages"]) > 100 and 0 < float(r["precision"]) <= 1
            assert int(r["scans_used"]) > 0 and float(r["duration_s"]) > 0
    assert list(rows[0]) == ["bag", "path", "status", "error", "duration_s", "messages",
                             *(c.name for c in JOBS["grid"].columns)]
    table = pq.read_table(out_dir / "fleet.parquet")
    assert table.column_names == list(rows[0])
    assert str(table.schema.field("messages").type) == "int64" and str(table.schema.field("recall").type) == "double"
    assert table.column("status").to_pylist() == [r["status"] for r in rows]
    assert table.column("messages").to_pylist()[2] is None
    assert (out_dir / "fleet.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"

    # Nothing else in DIR touched: the failed bags have no directory, the user's file is as it was.
    assert sorted(p.name for p in out_dir.iterdir()) == sorted(
        [BATCH_LOCK, BATCH_MANIFEST, "a__run1", "b__run1", "fleet.csv", "fleet.parquet", "fleet.png", "notes.txt", "run2",
         "run3"])
    assert (out_dir / "notes.txt").read_text() == "the user's own file"
    for name in ("a__run1", "b__run1", "run2", "run3"):
        assert sorted(p.name for p in (out_dir / name).iterdir()) == GRID_FILES
    assert json.loads((out_dir / "a__run1" / "summary.json").read_text())["bag"] == str(fleet.good[0])
    assert json.loads((out_dir / "b__run1" / "summary.json").read_text())["bag"] == str(fleet.good[1])
    done = {k: v for k, v in tree_state(out_dir).items() if not k.startswith("fleet.")}

    code, out, _ = _batch(argv, capsys)
    assert code == 1 and "6 bags: 0 ok, 4 skipped (done before), 2 failed" in out
    again = _rows(out_dir)
    assert [r["status"] for r in again] == ["skipped", "skipped", "failed", "failed", "skipped", "skipped"]
    for first, second in zip(rows, again):
        if first["status"] == "ok":  # the numbers of the run that did the work
            assert {k: v for k, v in first.items() if k != "status"} == {k: v for k, v in second.items() if k != "status"}
    assert {k: v for k, v in tree_state(out_dir).items() if not k.startswith("fleet.")} == done

    code, out, _ = _batch([*argv, "--force"], capsys)
    assert code == 1 and "6 bags: 4 ok, 0 skipped (done before), 2 failed" in out
    forced = tree_state(out_dir)
    for name in ("a__run1", "run3"):
        assert forced[f"{name}/map.pgm"][1] > done[f"{name}/map.pgm"][1]
    assert forced["notes.txt"] == done["notes.txt"]


def test_interrupted_with_ctrl_c_a_rerun_does_only_the_unfinished_bags(long_fleet: list[Path], tmp_path: Path,
                                                                        capsys) -> None:
    out_dir = tmp_path / "out"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")])}
    argv = ["ndt-odom", *map(str, long_fleet), "--out", str(out_dir), "--workers", "2"]
    proc = subprocess.Popen([sys.executable, "-m", "bagtools", "batch", *argv], env=env, cwd=REPO,
                            start_new_session=True, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 300  # generous: a loaded machine is slow, and the signal waits for a finished bag
    while not list(out_dir.glob(f"*/{MARKER}")) and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.05)
    assert proc.poll() is None, "the batch ended before a bag was seen finished: the fleet is too small to stop"
    assert list(out_dir.glob(f"*/{MARKER}")), "no bag finished within the deadline"
    os.killpg(proc.pid, signal.SIGINT)  # what Ctrl-C in a terminal does: the whole foreground group
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert "Traceback" not in err and "run the same command again to do the other" in err
    # the batch's own line ends stderr: no resource_tracker warning of semaphores the stopped workers left (#42)
    assert "leaked semaphore" not in err and err.strip().splitlines()[-1].startswith("bagtools: interrupted"), err
    finished = sorted(p.parent.name for p in out_dir.glob(f"*/{MARKER}"))
    assert 1 <= len(finished) < len(long_fleet), "the run must be stopped in the middle"
    assert not (out_dir / "fleet.csv").exists()

    code, out, err = _batch(argv, capsys)
    assert code == 0, err
    rows = _rows(out_dir)
    assert sorted(r["bag"] for r in rows if r["status"] == "skipped") == finished
    assert len([r for r in rows if r["status"] == "ok"]) == len(long_fleet) - len(finished)
    assert not [p for p in out_dir.rglob("*.tmp")]  # a bag stopped in the middle left nothing behind


def test_a_second_batch_into_the_same_directory_at_once_is_refused_and_the_first_runs(fleet: Fleet,
                                                                                        tmp_path: Path) -> None:
    """Two batches into one --out at once (#42): the second is refused in one line before any work, naming the
    first's pid; the first is not disturbed; once it has ended, the directory is free again."""
    from bagtools.batch.plan import lock_out_dir

    out_dir = tmp_path / "fleet"
    first, _ = lock_out_dir(out_dir)  # a batch running now
    argv = [sys.executable, "-m", "bagtools", "batch", "info", str(fleet.good[0]), "--out", str(out_dir)]
    done = subprocess.run(argv, capture_output=True, text=True, timeout=600)
    assert done.returncode == 2, done.stderr
    assert done.stderr.strip().splitlines() == [
        f"bagtools: {out_dir}: another batch (pid {os.getpid()}) is writing into this directory now; wait for it to "
        "end, or use another --out"]
    assert sorted(p.name for p in out_dir.iterdir()) == [BATCH_LOCK]
    os.close(first)  # the first batch ends
    done = subprocess.run(argv, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr


def test_a_batch_that_fails_as_a_whole_leaves_no_folder_lock_or_manifest(fleet: Fleet, tmp_path: Path) -> None:
    """No cluster to run on: exit 2 in one line, and the --out it would have made (two levels) is not left behind
    with a lock or a manifest in it (#42: a failed batch left .bagtools-batch.json)."""
    import socket

    with socket.socket() as s:  # a port nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    out_dir = tmp_path / "new" / "fleet"
    argv = [sys.executable, "-m", "bagtools", "batch", "info", str(fleet.good[0]), "--out", str(out_dir),
            "--scheduler", f"tcp://127.0.0.1:{port}"]
    done = subprocess.run(argv, capture_output=True, text=True, timeout=600)
    assert done.returncode == 2 and len(done.stderr.strip().splitlines()) == 1, done.stderr
    assert not (tmp_path / "new").exists()


SEATTLE = REPO.parent / "shared" / "data" / "radish" / "seattle.log.gz"


@pytest.mark.skipif(not SEATTLE.exists(), reason="needs ../shared/data/radish (a log whose slam runs for seconds)")
def test_ctrl_c_while_bags_run_ends_stderr_with_the_batchs_own_line(tmp_path: Path) -> None:
    """Ctrl-C with bags in the middle of their work (slam of a Radish log, seconds each): the last line is the
    batch's, not multiprocessing's resource tracker warning of the semaphores the stopped workers left (#42)."""
    bags = []
    for k in range(3):
        bags.append(tmp_path / "bags" / f"seattle{k}.log.gz")
        bags[-1].parent.mkdir(exist_ok=True)
        shutil.copyfile(SEATTLE, bags[-1])
    out_dir = tmp_path / "out"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")])}
    env.pop("PYTHONWARNINGS", None)
    argv = ["slam", *map(str, bags), "--out", str(out_dir), "--workers", "2", "--", "--no-odometry", "--no-mcap"]
    proc = subprocess.Popen([sys.executable, "-m", "bagtools", "batch", *argv], env=env, cwd=REPO,
                            start_new_session=True, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 300
    while not (out_dir / BATCH_MANIFEST).exists() and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.05)  # the manifest is written once the workers are up, just before the bags are handed out
    time.sleep(3.0)
    assert proc.poll() is None, "the batch ended before it could be stopped"
    proc.send_signal(signal.SIGINT)  # the batch's own process, as a terminal's Ctrl-C reaches it
    _, err = proc.communicate(timeout=180)
    assert proc.returncode == 130, err
    assert "leaked semaphore" not in err and err.strip().splitlines()[-1].startswith("bagtools: interrupted"), err
