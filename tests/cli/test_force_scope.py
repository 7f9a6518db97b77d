"""``--force`` replaces only what the run itself writes: ``--no-mcap --force`` keeps an earlier results.mcap."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

FIXTURE = Path(__file__).resolve().parents[2] / "fixtures" / "sim_lap_cloud_20s"


@pytest.mark.parametrize("command", ["slam", "ndt-odom", "grid", "map-cloud"])
def test_no_mcap_force_keeps_an_earlier_results_mcap(tmp_path: Path, command: str) -> None:
    out = tmp_path / "out"
    out.mkdir()
    earlier = out / "results.mcap"
    earlier.write_bytes(b"an earlier run's results")
    base = [sys.executable, "-m", "bagtools", command, str(FIXTURE), "--out", str(out), "--no-mcap"]
    done = subprocess.run(base, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr  # results.mcap is not this run's: no --force needed
    done = subprocess.run([*base, "--force"], capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    assert earlier.read_bytes() == b"an earlier run's results"


def test_map_cloud_without_refine_neither_needs_force_for_nor_removes_a_trajectory(tmp_path: Path) -> None:
    """trajectory.tum is map-cloud's only with --refine: a plain run leaves a user's file of that name alone."""
    out = tmp_path / "out"
    out.mkdir()
    mine = out / "trajectory.tum"
    mine.write_text("# my trajectory\n")
    base = [sys.executable, "-m", "bagtools", "map-cloud", str(FIXTURE), "--out", str(out), "--no-mcap"]
    for argv in (base, [*base, "--force"]):
        done = subprocess.run(argv, capture_output=True, text=True, timeout=600)
        assert done.returncode == 0, done.stderr
        assert mine.read_text() == "# my trajectory\n"
    done = subprocess.run([*base, "--refine"], capture_output=True, text=True, timeout=600)
    assert done.returncode == 2 and "already exists" in done.stderr  # the run's files are there
    done = subprocess.run([*base, "--refine", "--force"], capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    assert mine.read_text().startswith("# frame: odom") or mine.read_text().startswith("# frame: map")  # now the run's
