"""Bags for the batch tests: short simulated runs (one session-wide set), a corrupt bag and a bag without /scan.

The session set is read-only: tests copy nothing and write only under their
own ``tmp_path``.
"""

from __future__ import annotations

import shutil
import signal
from dataclasses import dataclass
from pathlib import Path

import pytest

from bagtools_simulate.pipeline import SimConfig, simulate_bag
from tests.conftest import make_tf, write_bag

T0_NS = 1_700_000_000_000_000_000


@pytest.fixture(scope="session", autouse=True)
def sigint_as_at_a_terminal():
    """The Ctrl-C tests need the processes they start to get SIGINT as a terminal's would. A test run started
    in the background of a shell (``make test &``) ignores SIGINT from its start, and every process it starts
    would inherit that: for the session, Python's own handler (which children inherit as the default)."""
    before = signal.getsignal(signal.SIGINT)
    if before == signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, before)


@dataclass(frozen=True)
class Fleet:
    """``root``: a folder of bags. ``good``: simulated bags (two of them both named run1, in a/ and b/),
    ``corrupt``: an MCAP cut to 1 KB, ``no_scan``: a rosbag2 bag with /tf only."""

    root: Path
    good: list[Path]
    corrupt: Path
    no_scan: Path

    @property
    def all(self) -> list[Path]:
        return [*self.good, self.corrupt, self.no_scan]


def simulated(path: Path, seed: int, duration_s: float = 5.0) -> Path:
    """A short simulated bag without depth clouds (scans, tf, odometry, ground truth)."""
    simulate_bag(path, SimConfig(duration_s=duration_s, seed=seed, cloud=False))
    return path


@pytest.fixture(scope="session")
def fleet(tmp_path_factory: pytest.TempPathFactory) -> Fleet:
    """Four 5 s simulated bags, a truncated MCAP and a bag without /scan, in one folder."""
    root = tmp_path_factory.mktemp("fleet")
    good = [simulated(root / "a" / "run1", 1), simulated(root / "b" / "run1", 2), simulated(root / "run2", 3),
            simulated(root / "run3", 4)]
    storage = next((root / "run2").glob("*.mcap"))
    corrupt = root / "corrupt.mcap"
    corrupt.write_bytes(storage.read_bytes()[:1024])
    tf = [("/tf", "tf2_msgs/msg/TFMessage", T0_NS + i * 100_000_000,
           make_tf(T0_NS + i * 100_000_000, "odom", "base_footprint", (0.01 * i, 0, 0), (0, 0, 0, 1)))
          for i in range(20)]
    no_scan = write_bag(root / "no_scan", tf)
    return Fleet(root, good, corrupt, no_scan)


@pytest.fixture(scope="session")
def long_fleet(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    """Six 10 s simulated bags, for runs that are stopped in the middle."""
    root = tmp_path_factory.mktemp("long_fleet")
    return [simulated(root / f"robot{i}", 10 + i, duration_s=10.0) for i in range(6)]


def tree_state(root: Path) -> dict[str, tuple[int, int]]:
    """Every file under ``root`` (hidden ones too) -> (size, mtime_ns): to check what a run touched."""
    return {str(p.relative_to(root)): (p.stat().st_size, p.stat().st_mtime_ns)
            for p in sorted(root.rglob("*")) if p.is_file()}


def copy_bag(bag: Path, dest: Path) -> Path:
    """A copy of ``bag`` (directory or file) at ``dest``."""
    if bag.is_dir():
        shutil.copytree(bag, dest)
    else:
        shutil.copy2(bag, dest)
    return dest
