"""``--force`` replaces only what the run itself writes: ``--no-mcap --force`` keeps an earlier results.mcap."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

FIXTURE = Path(__file__).resolve().parents[2] / "fixtures" / "sim_lap_cloud_20s"


@pytest.mark.parametrize("command", ["slam", "ndt-odom", "grid"])
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
