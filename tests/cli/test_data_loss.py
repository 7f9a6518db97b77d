"""No command loses a user's files: --force replaces only the command's own outputs, a failed run
changes nothing, SIGTERM cleans up, and stale staging of a killed run is removed by the next run."""

from __future__ import annotations

import hashlib
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

from bagtools.cli import main
from tests.conftest import FIXTURES, make_scan, write_bag

BAG = FIXTURES / "sim_lap_cloud_20s"


def run(argv: list[str], capsys) -> tuple[int, str, str]:
    with pytest.raises(SystemExit) as exit_info:
        main(argv)
    out = capsys.readouterr()
    return exit_info.value.code, out.out, out.err


def snapshot(root: Path) -> dict[str, tuple[int, str]]:
    """relative path -> (size, sha1) of every file and directory below ``root`` (hidden ones too)."""
    snap = {}
    for p in sorted(root.rglob("*")):
        snap[str(p.relative_to(root))] = (-1, "dir") if p.is_dir() else (p.stat().st_size, hashlib.sha1(p.read_bytes()).hexdigest())
    return snap


@pytest.fixture
def user_dir(tmp_path: Path) -> Path:
    d = tmp_path / "mine"
    (d / "sub").mkdir(parents=True)
    (d / "notes.txt").write_text("my notes")
    (d / "sub" / "photo.jpg").write_bytes(b"\xff\xd8 precious")
    return d


@pytest.mark.parametrize("argv", [
    ["tf", "echo", str(BAG), "odom", "base_footprint", "--csv", "{dir}", "--force"],
    ["tf", "frames", str(BAG), "--dot", "{dir}", "--force"],
    ["simulate", "{dir}", "--duration", "1", "--no-cloud", "--force"],
])
def test_force_refuses_a_directory_it_did_not_write(argv: list[str], user_dir: Path, capsys) -> None:
    before = snapshot(user_dir.parent)
    code, _, err = run([a.replace("{dir}", str(user_dir)) for a in argv], capsys)
    assert code == 2, err
    assert err.count("\n") == 1 and str(user_dir) in err and "did not write" in err
    assert snapshot(user_dir.parent) == before


def test_simulate_force_replaces_its_own_bag(tmp_path: Path, capsys) -> None:
    out = tmp_path / "sim"
    assert run(["simulate", str(out), "--duration", "1", "--no-cloud"], capsys)[0] == 0
    first = snapshot(out)
    code, _, err = run(["simulate", str(out), "--duration", "1", "--no-cloud"], capsys)
    assert code == 2 and "--force" in err and snapshot(out) == first
    assert run(["simulate", str(out), "--duration", "2", "--no-cloud", "--force"], capsys)[0] == 0
    assert snapshot(out) != first and sorted(p.name for p in tmp_path.iterdir()) == ["sim"]


def test_failed_ndt_odom_changes_nothing(tmp_path: Path, capsys) -> None:
    """Every scan unusable: exit 2, and an earlier good run's files (and the user's) stay as they were."""
    out = tmp_path / "out"
    assert run(["ndt-odom", str(BAG), "--out", str(out)], capsys)[0] == 0
    (out / "my_notes.txt").write_text("keep")
    before = snapshot(out)
    t0 = 1_700_000_000_000_000_000
    msgs = [("/scan", "sensor_msgs/msg/LaserScan", t0 + i * 200_000_000,
             make_scan(t0 + i * 200_000_000, np.full(360, np.nan, dtype=np.float32))) for i in range(10)]
    bad = write_bag(tmp_path / "nan_scans", msgs)
    code, _, err = run(["ndt-odom", str(bad), "--out", str(out), "--force"], capsys)
    assert code == 2 and "no usable scan" in err, err
    assert snapshot(out) == before


def _wait_for(predicate, timeout_s: float = 60.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not predicate():
        if time.monotonic() > deadline:
            raise AssertionError("timed out")
        time.sleep(0.05)


def test_sigterm_removes_staging_and_sigkill_staging_is_swept_by_the_next_run(tmp_path: Path) -> None:
    out = tmp_path / "sim"
    argv = [sys.executable, "-m", "bagtools", "simulate", str(out), "--duration", "600", "--no-cloud"]
    env = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[2]))

    proc = subprocess.Popen(argv, stderr=subprocess.PIPE, text=True, env=env)
    _wait_for(lambda: any(p.name.startswith(".sim.") for p in tmp_path.iterdir()))
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 128 + signal.SIGTERM, err
    assert "Traceback" not in err and "terminated" in err
    assert list(tmp_path.iterdir()) == []

    proc = subprocess.Popen(argv, stderr=subprocess.DEVNULL, env=env)
    _wait_for(lambda: any(p.name.startswith(".sim.") for p in tmp_path.iterdir()))
    proc.kill()
    proc.wait()
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".sim.")]  # SIGKILL leaves staging behind
    result = subprocess.run(argv[:5] + ["--duration", "1", "--no-cloud"], capture_output=True, text=True, env=env)
    assert result.returncode == 0, result.stderr
    assert [p.name for p in tmp_path.iterdir()] == ["sim"]


def test_a_sigterm_raised_where_python_ignores_exceptions_is_delivered_again() -> None:
    """A signal that arrives while Python runs a weakref or import-lock callback raises there, and Python can only
    print and ignore the exception (CI saw a SIGTERM lost that way, mid-import: exit 0, the run completed). The
    command's unraisable hook sends it again, and it ends the command."""
    script = textwrap.dedent("""
        import gc, signal, sys, time, weakref
        from bagtools.cli import Terminated, _deliver_again, _raise_terminated
        signal.signal(signal.SIGTERM, _raise_terminated)
        sys.unraisablehook = _deliver_again
        class Held: pass
        held = Held()
        probe = weakref.ref(held, lambda ref: signal.raise_signal(signal.SIGTERM))
        try:
            del held
            gc.collect()
            for _ in range(500):
                time.sleep(0.002)
            print("lost")
        except Terminated as exc:
            print("delivered", exc.signum)
    """)
    env = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[2]))
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, env=env, timeout=60)
    assert done.stdout.strip() == f"delivered {int(signal.SIGTERM)}", (done.stdout, done.stderr)
    assert "Exception ignored" not in done.stderr
