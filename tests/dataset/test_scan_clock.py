"""Scans whose stamps cannot time them (all zero, all equal, going backwards) are taken in logging order."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from bagtools.dataset import LOGGING_ORDER_STEP_NS, ScanStream, scan_clock
from bagtools.io import open_bag
from bagtools.io.carmen import write_flaser_log
from bagtools.trajectory import read_tum

FIXTURE = Path(__file__).resolve().parents[2] / "fixtures" / "sim_lap_cloud_20s"


def _log_with_stamps(tmp_path: Path, stamp_of, bag: Path = FIXTURE) -> tuple[Path, int]:
    """``bag``'s scans as a CARMEN log whose laser lines are stamped ``stamp_of(k)`` (text)."""
    clf = tmp_path / "full.clf"
    write_flaser_log(bag, clf)
    out, k = [], 0
    for line in clf.read_text().splitlines():
        words = line.split()
        if words and words[0] == "FLASER":
            words[-3] = words[-1] = stamp_of(k)
            k += 1
            out.append(" ".join(words))
        elif words and words[0] == "PARAM":
            out.append(line)
    log = tmp_path / "stamps.clf"
    log.write_text("\n".join(out) + "\n")
    return log, k


@pytest.mark.parametrize("stamp_of,why", [
    (lambda k: "0.000000", "every stamp is 0.000000000 s"),
    (lambda k: "1234.567890", "every stamp is 1234.567890000 s"),
    # six significant digits (C's %g) of a clock near 1.1e9 s: all equal, written in exponent form
    (lambda k: f"{1.1e9 + 0.2 * k:.6g}", "every stamp is 1100000000.000000000 s"),
    # the same clock where it crosses one of those digits' steps: equal but for one step
    (lambda k: f"{1.1e9 + 4995 + 0.2 * k:.6g}", "99 of 100 stamps are not after the one before"),
])
def test_unusable_stamps_are_replaced_by_logging_order(tmp_path: Path, stamp_of, why: str) -> None:
    log, n = _log_with_stamps(tmp_path, stamp_of)
    with open_bag(log) as bag:
        clock = scan_clock(bag, "/scan")
        assert not clock.usable and clock.why == why
        stream = ScanStream(bag, "/scan", clock=clock, increasing=True, desc=None)
        stamps = [item.scan.stamp_ns for item in stream]
    assert len(stamps) == n and np.all(np.diff(stamps) == LOGGING_ORDER_STEP_NS)  # every scan, none skipped
    assert stream.warnings() == [clock.warning("/scan")]


def test_usable_stamps_are_kept(tmp_path: Path) -> None:
    with open_bag(FIXTURE) as bag:
        assert scan_clock(bag, "/scan").usable


def _run(command: str, log: Path, out: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "bagtools", command, str(log), "--out", str(out), "--no-odometry",
                           "--no-mcap"], capture_output=True, text=True, timeout=600)


def test_slam_and_ndt_odom_place_every_scan_of_a_log_stamped_zero(tmp_path: Path) -> None:
    """Every scan gets a pose, in logging order, said once; the path is the one the true stamps give."""
    log, n = _log_with_stamps(tmp_path, lambda k: "0.000000")
    (tmp_path / "timed").mkdir()
    timed, _ = _log_with_stamps(tmp_path / "timed", lambda k: f"{100 + 0.2 * k:.6f}")
    for command in ("slam", "ndt-odom"):
        done = _run(command, log, tmp_path / command)
        assert done.returncode == 0, done.stderr
        assert done.stderr.count("cannot time its scans") == 1, done.stderr  # said once
        summary = json.loads((tmp_path / command / "summary.json").read_text())
        assert (summary.get("front_end") or summary)["stamps_ignored"] == "every stamp is 0.000000000 s"
        trajectory = read_tum(tmp_path / command / "trajectory.tum")
        assert len(trajectory) == n and np.all(np.diff(trajectory.stamps_ns) == LOGGING_ORDER_STEP_NS)
        assert _run(command, timed, tmp_path / f"{command}_timed").returncode == 0
        reference = read_tum(tmp_path / f"{command}_timed" / "trajectory.tum")
        assert np.ptp(reference.positions[:, :2], axis=0).max() > 0.3  # the robot moves
        # without the stamps the motion model knows less (every step 1 s): the same path, less closely
        assert np.abs(trajectory.positions - reference.positions).max() < 0.25


def test_a_log_whose_clock_runs_backwards_is_taken_in_its_lines_order(tmp_path: Path) -> None:
    """Every stamp before the one on the line before it: a CARMEN log's lines are its recording order (its reader
    sorts them by stamp), so the clock is judged in that order, ignored, and the scans taken in line order."""
    log, n = _log_with_stamps(tmp_path, lambda k: f"{5000 - 0.2 * k:.6f}")
    with open_bag(log) as bag:
        clock = scan_clock(bag, "/scan")
        assert not clock.usable and clock.why == f"{n - 1} of {n - 1} stamps are not after the one before"
        items = list(ScanStream(bag, "/scan", clock=clock, increasing=True, desc=None))
    assert len(items) == n  # none skipped as going backwards
    # the k-th line (header.seq k) is stamped k seconds after the first line's stamp, whatever order the bag gave
    assert all(item.scan.stamp_ns == clock.first_ns + item.seq * LOGGING_ORDER_STEP_NS for item in items)
    assert clock.first_ns == 5000 * 10**9


def test_a_clock_that_restarts_half_way_is_ignored_and_the_lines_order_kept(tmp_path: Path) -> None:
    """A logger's clock reset half way: the second half is stamped before the first, farther from its line than a
    stamp's jitter moves a scan. Its stamps cannot order the log (the two halves would interleave, some stamped
    alike): they are ignored, said once, and every scan is taken in line order, 1 s apart: the path the true
    stamps give."""
    from bagtools_simulate.pipeline import SimConfig, simulate_bag

    bag = tmp_path / "lap"
    simulate_bag(bag, SimConfig(duration_s=70.0, cloud=False, seed=5))
    half = 175  # of 350 scans at 5 Hz: the second half's stamps move them 175 places, beyond MAX_REORDER_SCANS
    log, n = _log_with_stamps(tmp_path, lambda k: f"{(100 + 0.2 * k) if k < half else (10 + 0.2 * k):.6f}", bag)
    (tmp_path / "timed").mkdir()
    timed, _ = _log_with_stamps(tmp_path / "timed", lambda k: f"{100 + 0.2 * k:.6f}", bag)
    assert n > 2 * half - 5
    done = _run("ndt-odom", log, tmp_path / "reset")
    assert done.returncode == 0, done.stderr
    assert done.stderr.count("cannot time its scans (the clock went back:") == 1, done.stderr
    assert _run("ndt-odom", timed, tmp_path / "timed_out").returncode == 0
    got, want = read_tum(tmp_path / "reset" / "trajectory.tum"), read_tum(tmp_path / "timed_out" / "trajectory.tum")
    assert len(got) == len(want) == n and np.all(np.diff(got.stamps_ns) == LOGGING_ORDER_STEP_NS)
    # per scan, not per second, the laser odometry drifts its own way (0.55 m at most over these 15 m); the two
    # halves interleaved by their stamps would put scans metres from their place
    assert np.hypot(*(got.positions - want.positions)[:, :2].T).max() < 1.0
