"""The four shifted NDT grids of a reference scan."""

from __future__ import annotations

import numpy as np
import pytest

from bagtools.scan_matching import NdtReference
from bagtools.scan_matching.grid import MAJOR_AXIS_INFLATION, MIN_EIGENVALUE_RATIO, RESIDUAL_COVARIANCE_FACTOR


def cell_of(ref: NdtReference, point) -> np.ndarray:
    """(6, 4) table columns of the cells holding ``point`` in the four grids."""
    return ref.lookup(np.asarray(point, float).reshape(2, 1))[:, :, 0]


@pytest.mark.parametrize("cell_model", ["paper", "widened"])
def test_collinear_points_get_a_regularized_covariance(cell_model):
    xs = np.linspace(0.1, 0.4, 7)
    ref = NdtReference.from_points(np.column_stack((xs, np.full(7, 0.3))), cell_size=1.0, cell_model=cell_model)
    mx, my, a, b, c, w = cell_of(ref, (0.25, 0.3))
    assert np.all(w == 1.0)  # all 7 points are in one cell of every grid
    np.testing.assert_allclose(mx, 0.25)
    np.testing.assert_allclose(my, 0.3)
    cov = np.linalg.inv(np.array([[a[0], b[0]], [b[0], c[0]]]))
    var_x = np.var(xs)  # 1/n normalization
    minor = MIN_EIGENVALUE_RATIO * var_x  # the paper: smallest eigenvalue raised to 0.001 of the largest
    if cell_model == "paper":
        expected = np.array([minor, var_x])
    else:  # major spread widened, both doubled (residual of two scans)
        expected = RESIDUAL_COVARIANCE_FACTOR * np.array([minor, minor + MAJOR_AXIS_INFLATION * (var_x - minor)])
    np.testing.assert_allclose(np.sort(np.linalg.eigvalsh(cov)), expected, rtol=1e-9)


def test_unknown_cell_model_is_a_value_error():
    with pytest.raises(ValueError, match="cell_model must be one of paper, widened"):
        NdtReference.from_points(np.zeros((10, 2)), cell_model="wide")


def test_major_axis_is_widened_along_its_own_direction():
    rng = np.random.default_rng(1)
    t = rng.uniform(-0.3, 0.3, 200)
    n = rng.normal(0.0, 0.02, 200)
    direction = np.array([np.cos(0.6), np.sin(0.6)])
    normal = np.array([-direction[1], direction[0]])
    pts = 0.5 + t[:, None] * direction + n[:, None] * normal
    ref = NdtReference.from_points(pts, cell_size=2.0, cell_model="widened")
    mx, my, a, b, c, w = cell_of(ref, pts.mean(axis=0))
    assert np.all(w == 1.0)
    cov = np.linalg.inv(np.array([[a[0], b[0]], [b[0], c[0]]]))
    sample = np.cov(pts.T, bias=True)
    values, vectors = np.linalg.eigh(sample)
    major = values[0] + MAJOR_AXIS_INFLATION * (values[1] - values[0])
    widened = vectors @ np.diag(RESIDUAL_COVARIANCE_FACTOR * np.array([values[0], major])) @ vectors.T
    np.testing.assert_allclose(cov, widened, rtol=1e-7)


def test_round_cells_stay_round():
    angles = np.linspace(0, 2 * np.pi, 24, endpoint=False)
    pts = 0.3 + 0.1 * np.column_stack((np.cos(angles), np.sin(angles)))
    ref = NdtReference.from_points(pts, cell_size=2.0, cell_model="widened")
    mx, my, a, b, c, w = cell_of(ref, (0.3, 0.3))
    cov = np.linalg.inv(np.array([[a[0], b[0]], [b[0], c[0]]]))
    np.testing.assert_allclose(cov, RESIDUAL_COVARIANCE_FACTOR * 0.005 * np.eye(2), atol=1e-12)


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
