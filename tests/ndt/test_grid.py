"""The four shifted NDT grids of a reference scan."""

from __future__ import annotations

import numpy as np
import pytest

from bagtools.ndt import NdtReference
from bagtools.ndt.grid import MIN_EIGENVALUE_RATIO


def cell_of(ref: NdtReference, point) -> np.ndarray:
    """(6, 4) table columns of the cells holding ``point`` in the four grids."""
    return ref.lookup(np.asarray(point, float).reshape(2, 1))[:, :, 0]


def test_collinear_points_get_a_regularized_covariance():
    xs = np.linspace(0.1, 0.4, 7)
    ref = NdtReference.from_points(np.column_stack((xs, np.full(7, 0.3))), cell_size=1.0)
    mx, my, a, b, c, w = cell_of(ref, (0.25, 0.3))
    assert np.all(w == 1.0)  # all 7 points are in one cell of every grid
    np.testing.assert_allclose(mx, 0.25)
    np.testing.assert_allclose(my, 0.3)
    cov = np.linalg.inv(np.array([[a[0], b[0]], [b[0], c[0]]]))
    var_x = np.var(xs)  # 1/n normalization
    np.testing.assert_allclose(np.sort(np.linalg.eigvalsh(cov)), [MIN_EIGENVALUE_RATIO * var_x, var_x], rtol=1e-9)


def test_grids_are_shifted_by_half_a_cell():
    pts = np.array([[0.9, 0.2], [0.95, 0.25], [0.97, 0.22], [1.03, 0.2], [1.05, 0.25], [1.1, 0.22]])
    ref = NdtReference.from_points(pts, cell_size=1.0)
    assert ref.n_cells == 4  # the six points share one cell in each grid
    np.testing.assert_array_equal(cell_of(ref, (1.0, 0.22))[5], 1.0)
    # The grid edges differ by half a cell: in x between grids 0 and 1, in y between 0 and 2.
    np.testing.assert_allclose(ref.origins[0] - ref.origins[1], [0.5, 0.0])
    np.testing.assert_allclose(ref.origins[0] - ref.origins[2], [0.0, 0.5])
    np.testing.assert_allclose(ref.origins[0] - ref.origins[3], [0.5, 0.5])
    # 0.55 m to the left is outside the unshifted cell but inside the x-shifted one.
    np.testing.assert_array_equal(cell_of(ref, (0.45, 0.22))[5], [0.0, 1.0, 0.0, 1.0])


def test_two_points_per_cell_make_no_distribution():
    pts = np.array([[0.0, 0.0], [0.1, 0.0], [5.0, 5.0], [5.1, 5.0]])
    assert NdtReference.from_points(pts).n_cells == 0


def test_far_away_lookups_land_in_empty_cells():
    rng = np.random.default_rng(0)
    ref = NdtReference.from_points(rng.uniform(-2, 2, (4000, 2)), cell_size=0.5)
    far = np.array([[1e6, -1e6, 30.0, -30.0, 2.3], [1e6, 1e6, 0.0, 0.0, -40.0]])
    assert np.all(ref.lookup(far)[5] == 0.0)
    assert np.all(ref.lookup(np.array([[0.0], [0.0]]))[5] == 1.0)


def test_bad_cell_size_raises():
    with pytest.raises(ValueError, match="cell_size"):
        NdtReference.from_points(np.zeros((5, 2)), cell_size=-1.0)
