"""tf repair's running median: scipy.ndimage's, value for value, without importing scipy.ndimage (#44: 0.2 s of
every command that reads tf, `bagtools info` included)."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
from scipy.ndimage import median_filter

from bagtools.tf.repair import _median_filter


@pytest.mark.parametrize("seed", range(6))
def test_running_median_equals_scipys(seed: int) -> None:
    rng = np.random.default_rng(seed)
    for _ in range(60):
        n, cols, window = int(rng.integers(1, 80)), int(rng.integers(1, 5)), int(rng.integers(1, 12))
        rows = rng.normal(size=(n, cols)) if seed % 2 else rng.integers(0, 4, size=(n, cols)).astype(np.float64)
        np.testing.assert_array_equal(_median_filter(rows, window), median_filter(rows, size=(window, 1),
                                                                                  mode="nearest"))


def test_info_does_not_import_scipy_ndimage() -> None:
    code = "import sys, bagtools.commands.info, bagtools.tf.repair; print('scipy.ndimage' in sys.modules)"
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0 and done.stdout.strip() == "False", done.stdout + done.stderr
