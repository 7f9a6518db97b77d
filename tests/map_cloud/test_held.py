"""map-cloud reads a bag once and holds its clouds until tf is known: in memory up to a budget, then on disk."""

from __future__ import annotations

from pathlib import Path

import numpy as np

import bagtools.commands.map_cloud.pipeline as pipeline
from bagtools.commands.map_cloud import CloudMapOptions, CloudMapPipeline
from bagtools.cloud.accumulator import MapCloud
from bagtools.commands.map_cloud.held import HELD_PREFIX, HeldCloud, HeldClouds
from tests.conftest import FIXTURES

LAP = FIXTURES / "sim_lap_cloud_20s"


def test_held_clouds_come_back_in_order_from_memory_and_disk() -> None:
    held = HeldClouds(budget_bytes=5000)
    rng = np.random.default_rng(0)
    clouds = [HeldCloud(i, i + 1, "cam", MapCloud(rng.random((50 + i, 3)).astype(np.float32))) for i in range(40)]
    for c in clouds:
        held.add(c)
    assert held.spilled_batches > 3 and held.count == 40
    directory = Path(held._dir.name)
    back = list(held)
    assert [c.stamp_ns for c in back] == list(range(40))
    assert all(np.array_equal(a.cloud.points, b.cloud.points) for a, b in zip(back, clouds))
    held.close()
    assert not directory.exists()


def test_a_map_held_on_disk_is_the_map_held_in_memory(monkeypatch) -> None:
    options = CloudMapOptions(sample=0.5, voxel_m=0.02)
    in_memory = CloudMapPipeline(LAP, options).run()
    spilled: list[HeldClouds] = []

    class Small(HeldClouds):
        def __init__(self) -> None:
            super().__init__(budget_bytes=16 * 1024)
            spilled.append(self)

    monkeypatch.setattr(pipeline, "HeldClouds", Small)
    on_disk = CloudMapPipeline(LAP, options).run()
    assert spilled and spilled[0].spilled_batches > 3
    assert np.array_equal(in_memory.points, on_disk.points)
    assert in_memory.summary["clouds_used"] == on_disk.summary["clouds_used"] > 0


def test_a_killed_runs_spill_is_removed_by_the_next(tmp_path: Path, monkeypatch) -> None:
    """SIGKILL during map-cloud left bagtools-held-* (7 MB) behind for good; the next spilling run removes the
    directories whose process is gone, and only those."""
    import subprocess
    import sys
    import tempfile

    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    orphan = tmp_path / f"{HELD_PREFIX}{int(dead.stdout)}-abc"
    orphan.mkdir()
    (orphan / "000000.pickle").write_bytes(b"x" * 1000)
    mine = tmp_path / f"{HELD_PREFIX}{__import__('os').getpid()}-def"
    mine.mkdir()
    held = HeldClouds(budget_bytes=100)
    held.add(HeldCloud(0, 1, "cam", MapCloud(np.zeros((50, 3), np.float32))))
    assert held.spilled_batches == 1 and not orphan.exists() and mine.exists()
    held.close()


def test_a_full_temporary_directory_is_named(tmp_path: Path, monkeypatch) -> None:
    """It was said as 'No space left on device' naming the bag."""
    import errno

    import pytest

    from bagtools.errors import BagtoolsError

    held = HeldClouds(budget_bytes=100)

    def full(*args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(Path, "open", full)
    with pytest.raises(BagtoolsError, match="cannot hold clouds there while tf is read") as info:
        held.add(HeldCloud(0, 1, "cam", MapCloud(np.zeros((50, 3), np.float32))))
    assert info.value.path is not None and HELD_PREFIX in info.value.path  # the temporary directory, not the bag
    held.close()
