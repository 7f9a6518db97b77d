"""Correlative scan matching (match_scans_grid) on synthetic LDS-01 scan pairs in the TurtleBot3 world."""

from __future__ import annotations

import numpy as np
import pytest

from bagtools.ndt import CorrelativeReference, GridMatchResult, match_scans, match_scans_grid, match_scans_grid_ranges
from bagtools.ndt import correlative
from bench.scan_pairs import ANGLES_RAD, scan_pairs

TRANS_TOL_M = 0.02
ROT_TOL_RAD = np.radians(0.5)
WINDOW = (0.3, 0.3, 0.3)


@pytest.fixture(scope="module")
def pairs():
    return scan_pairs(8, seed=21)


def pose_error(estimate: np.ndarray, truth: np.ndarray) -> tuple[float, float]:
    d = estimate - truth
    return float(np.hypot(d[0], d[1])), float(abs((d[2] + np.pi) % (2 * np.pi) - np.pi))


def assert_same_candidate(a: GridMatchResult, b: GridMatchResult) -> None:
    assert a.ok and b.ok, (a.reason, b.reason)
    assert a.index == b.index
    assert a.score == b.score
    np.testing.assert_array_equal(a.pose, b.pose)


def test_branch_and_bound_equals_exhaustive_search(pairs):
    for pair in pairs[:4]:
        reference = CorrelativeReference.from_points(pair.reference_points)
        bnb = match_scans_grid(pair.current_points, reference, search_range=WINDOW)
        full = match_scans_grid(pair.current_points, reference, search_range=WINDOW, method="exhaustive")
        assert_same_candidate(bnb, full)
        assert bnb.n_evaluated < full.n_evaluated == full.n_candidates
