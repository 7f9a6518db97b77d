"""What a new user trips over first: `bagtools` alone, an unknown frame, `help(bagtools)`."""

from __future__ import annotations

import pkgutil
import subprocess
import sys
from pathlib import Path

import bagtools


def run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "bagtools", *args], capture_output=True, text=True, timeout=120)


def test_bagtools_alone_prints_the_help_and_exits_0() -> None:
    result = run()
    assert result.returncode == 0, result.stderr
    assert "Usage: bagtools" in result.stdout and "slam" in result.stdout and result.stderr == ""


def test_an_unknown_frame_is_said_with_the_nearest_names(synthetic_bag: Path) -> None:
    result = run("tf", "echo", str(synthetic_bag), "odom", "base_lnk")
    assert result.returncode == 2
    line = result.stderr.strip()
    assert line == (f"bagtools: {synthetic_bag}: frame 'base_lnk' is not in the bag's tf (nearest by name: base_link, "
                    "base_scan, odom; 3 frame(s) in all, see `bagtools tf frames`)"), line


def test_the_package_docstring_maps_every_subpackage() -> None:
    names = [m.name for m in pkgutil.iter_modules(bagtools.__path__) if not m.name.startswith("_")]
    missing = [n for n in names if f"``{n}``" not in bagtools.__doc__]
    assert not missing, missing
