"""map-cloud reads a bag once and holds its clouds until tf is known: in memory up to a budget, then on disk."""

from __future__ import annotations

from pathlib import Path

import numpy as np

import bagtools.cloudmap.pipeline as pipeline
from bagtools.cloudmap import CloudMapOptions, CloudMapPipeline
from bagtools.cloudmap.accumulator import MapCloud
from bagtools.cloudmap.held import HeldCloud, HeldClouds
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
