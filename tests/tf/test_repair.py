"""Repairs of recorded tf data: corrupt samples."""

from __future__ import annotations

import numpy as np

from bagtools.io import TfArrays
from bagtools.tf.repair import drop_translation_spikes, translation_spike_mask

T0 = 1_700_000_000_000_000_000
S = 1_000_000_000


def test_drop_translation_spikes() -> None:
    n = 50
    stamps = T0 + np.arange(n, dtype=np.int64) * S // 10
    xyz = np.column_stack([np.arange(n) * 0.02, np.zeros(n), np.zeros(n)])
    xyz[30:, 1] += 0.5                     # a localizer step: kept
    xyz[10, 1] = 1.9e32                    # a corrupt sample: dropped
    xyz[20:22, 0] = 5.9e22                 # two in a row: dropped
    q = np.tile([0.0, 0.0, 0.0, 1.0], (n, 1))
    arrays = TfArrays(np.array(["odom"] * n, dtype=object), np.array(["base_link"] * n, dtype=object), stamps, xyz, q)
    keep, dropped = translation_spike_mask(arrays)
    assert dropped == {("odom", "base_link"): 3}
    warnings: list[str] = []
    kept, keep_again = drop_translation_spikes(arrays, warnings)
    assert np.array_equal(keep, keep_again)
    assert warnings == ["dropped 3 corrupt /tf samples odom -> base_link (translation leaping away from its neighbours and back)"]
    assert len(kept) == n - 3 and np.abs(kept.translation).max() < 2.0
    assert set(kept.stamp_ns) == set(stamps) - {stamps[10], stamps[20], stamps[21]}


def test_from_bag_repairs_corrupt_odometry_of_a_real_bag(real_dir) -> None:
    from bagtools.tf import TfBuffer

    buffer = TfBuffer.from_bag(real_dir / "turtlebot3_real_lidar_odom.bag")
    assert any("dropped 8 corrupt /tf samples odom -> base_link" in w for w in buffer.warnings)
    first, last = buffer.time_range("odom", "base_link")
    stamps = first + (np.arange(2000, dtype=np.int64) * (last - first)) // 1999
    T = buffer.lookup("odom", "base_link", stamps)
    assert np.abs(T[:, :3, 3]).max() < 5.0  # the robot stays in its small arena


def test_from_arrays_repairs_only_when_asked() -> None:
    from bagtools.tf import TfBuffer

    n = 20
    xyz = np.column_stack([np.arange(n) * 0.02, np.zeros(n), np.zeros(n)])
    xyz[7, 0] = 1e30
    arrays = TfArrays(np.array(["odom"] * n, dtype=object), np.array(["base"] * n, dtype=object),
                      T0 + np.arange(n, dtype=np.int64) * S // 10, xyz, np.tile([0.0, 0.0, 0.0, 1.0], (n, 1)))
    raw = TfBuffer.from_arrays(arrays)
    assert raw.lookup("odom", "base", int(arrays.stamp_ns[7]))[0, 3] == 1e30
    repaired = TfBuffer.from_arrays(arrays, repair_spikes=True)
    assert abs(repaired.lookup("odom", "base", int(arrays.stamp_ns[7]))[0, 3] - 0.14) < 1e-9
    assert repaired.warnings == ["dropped 1 corrupt /tf samples odom -> base (translation leaping away from its neighbours and back)"]
