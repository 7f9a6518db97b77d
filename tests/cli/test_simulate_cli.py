"""`bagtools simulate` through the real console entry point: output, summary, refusals and bad arguments."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest


def run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "bagtools", "simulate", *args], capture_output=True, text=True, timeout=120)


def test_writes_a_bag_and_prints_a_summary(tmp_path: Path) -> None:
    out = tmp_path / "sim"
    result = run(str(out), "--duration", "3", "--cloud-size", "32x24", "--route", "figure8", "--ros-distro", "humble")
    assert result.returncode == 0, result.stderr
    assert (out / "metadata.yaml").exists() and (out / "sim.mcap").exists()
    assert "/odom: 91 messages" in result.stdout and "/camera/depth/points: 7 messages" in result.stdout
    assert "distance driven:" in result.stdout and "final odometry drift:" in result.stdout
    again = run(str(out), "--duration", "3")
    assert again.returncode == 2
    assert again.stderr.strip() == f"bagtools: {out}: already exists (use --force to overwrite)"
    assert run(str(out), "--duration", "1", "--no-cloud", "--force").returncode == 0


def test_help_has_an_example() -> None:
    result = run("--help")
    assert result.returncode == 0
    assert "Example:" in result.stdout and "bagtools simulate out/sim" in result.stdout


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--duration", "-5"], "--duration must be a positive number"),
        (["--max-linear", "0.5"], "--max-linear must be in (0, 0.26]"),
        (["--max-linear", "0"], "--max-linear must be in (0, 0.26]"),
        (["--max-angular", "3"], "--max-angular must be in (0, 1.82]"),
        (["--cloud-size", "640by480"], "--cloud-size must look like WIDTHxHEIGHT"),
        (["--cloud-rate", "-1"], "--cloud-rate must be in (0, 30]"),
        (["--world", "no_such_world.json"], "no_such_world.json"),
    ],
)
def test_bad_arguments_give_one_line_and_exit_2(tmp_path: Path, args: list[str], message: str) -> None:
    out = tmp_path / "sim"
    result = run(str(out), *args)
    assert result.returncode == 2, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("bagtools: ") and message in lines[0], result.stderr
    assert "Traceback" not in result.stderr
    assert not out.exists()


def test_unknown_route_choice_is_rejected(tmp_path: Path) -> None:
    result = run(str(tmp_path / "sim"), "--route", "spiral")
    assert result.returncode == 2 and "Traceback" not in result.stderr
    assert "spiral" in result.stderr
