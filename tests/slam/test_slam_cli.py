"""``bagtools slam`` as a command: help, refusals before any work, one-line errors with exit status 2."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from tests.conftest import FIXTURES


def _run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "bagtools", *args], capture_output=True, text=True)


def test_help_has_an_example_and_says_the_resolution_unit() -> None:
    out = _run("slam", "--help")
    assert out.returncode == 0 and "Example:" in out.stdout and "bagtools slam out/sim --out out/slam" in out.stdout
    assert "METRES" in out.stdout and "--no-odometry" in out.stdout and "--loop-search-radius" in out.stdout


@pytest.mark.parametrize("args,message", [
    (["--topic", "/laser"], "no topic '/laser' in the bag (LaserScan topics: /scan"),
    (["--resolution", "0"], "--resolution must be a cell side between"),
    (["--max-range", "-2"], "--max-range must be a positive number of metres"),
    (["--loop-search-radius", "nan"], "--loop-search-radius must be a positive number of metres"),
    (["--loop-min-score", "1.5"], "--loop-min-score must be in [0, 1]"),
])
def test_bad_input_is_one_line(tmp_path: Path, args: list[str], message: str) -> None:
    bag = FIXTURES / "sim_random_nocloud_20s"
    done = _run("slam", str(bag), "--out", str(tmp_path / "out"), *args)
    assert done.returncode == 2 and done.stderr.count("\n") == 1, done.stderr
    assert done.stderr.startswith(f"bagtools: {bag}: ") and message in done.stderr
    assert not (tmp_path / "out").exists()


def test_missing_bag_and_existing_outputs(tmp_path: Path) -> None:
    done = _run("slam", str(tmp_path / "nothing.mcap"), "--out", str(tmp_path / "out"))
    assert done.returncode == 2 and done.stderr.count("\n") == 1 and "nothing.mcap" in done.stderr
    out = tmp_path / "out"
    out.mkdir()
    (out / "map.pgm").write_text("mine")
    done = _run("slam", str(FIXTURES / "sim_random_nocloud_20s"), "--out", str(out))
    assert done.returncode == 2 and "already exists (use --force to overwrite)" in done.stderr
    assert (out / "map.pgm").read_text() == "mine"
