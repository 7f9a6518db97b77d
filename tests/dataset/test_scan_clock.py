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


def _log_with_stamps(tmp_path: Path, stamp_of) -> tuple[Path, int]:
    """The fixture's scans as a CARMEN log whose laser lines are stamped ``stamp_of(k)`` (text)."""
    clf = tmp_path / "full.clf"
    write_flaser_log(FIXTURE, clf)
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
