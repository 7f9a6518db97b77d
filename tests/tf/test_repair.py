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
