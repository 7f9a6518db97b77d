"""OccupancyGrid: MATLAB insertRay semantics, thresholds, saturation, conversions, growth."""

from __future__ import annotations

import numpy as np
import pytest

from bagtools.grid.occupancy import GROW_STEP_CELLS, OccupancyGrid

P_FREE, P_OCC = 0.4, 0.7


def grid_10cm() -> OccupancyGrid:
    """2 m x 2 m, 10 cells per metre, bottom-left at (0, 0)."""
    return OccupancyGrid(2.0, 2.0, 10.0)


def cell_centre(col: int, row_up: int) -> np.ndarray:
    return np.array([[(col + 0.5) * 0.1, (row_up + 0.5) * 0.1]])


def test_single_beam_free_cells_and_occupied_end():
    grid = grid_10cm()
    grid.insert_ray([0.05, 1.05, 0.0], [0.5], [0.0], max_range=3.0)
    p = grid.occupancy_matrix()
    row = grid.world2grid([0.05, 1.05])[0, 0]
    np.testing.assert_allclose(p[row, :5], P_FREE, atol=1e-6)
    np.testing.assert_allclose(p[row, 5], P_OCC, atol=1e-6)
    untouched = np.ones_like(p, dtype=bool)
    untouched[row, :6] = False
    np.testing.assert_allclose(p[untouched], 0.5)


def test_pose_heading_rotates_beams():
    grid = grid_10cm()
    # heading +90 deg, beam at +90 deg in the sensor frame: points along -x
    grid.insert_ray([1.05, 1.05, np.pi / 2], [0.4], [np.pi / 2], max_range=3.0)
    np.testing.assert_allclose(grid.get_occupancy(cell_centre(6, 10)), P_OCC, atol=1e-6)
    np.testing.assert_allclose(grid.get_occupancy(cell_centre(7, 10)), P_FREE, atol=1e-6)
    np.testing.assert_allclose(grid.get_occupancy(cell_centre(10, 10)), P_FREE, atol=1e-6)


@pytest.mark.parametrize("reading", [1.0, 1.7, np.inf])
def test_range_at_or_beyond_max_range_marks_free_up_to_max_range_only(reading):
    grid = grid_10cm()
    grid.insert_ray([0.05, 0.05, 0.0], [reading], [0.0], max_range=1.0)
    p = grid.occupancy_matrix()[-1]
    np.testing.assert_allclose(p[:11], P_FREE, atol=1e-6)  # up to x = 0.05 + 1.0 m, last cell included
    np.testing.assert_allclose(p[11:], 0.5)
    assert not np.any(grid.check_occupancy(grid.cell_centers().reshape(-1, 2)) == 1)


def test_nan_ranges_are_ignored():
    angles = np.linspace(-1, 1, 9)
    ranges = np.full(9, 0.8)
    with_nan = ranges.copy()
    with_nan[[1, 4, 7]] = np.nan
    a, b = grid_10cm(), grid_10cm()
    a.insert_ray([1.0, 1.0, 0.3], with_nan, angles, 3.0)
    keep = ~np.isnan(with_nan)
    b.insert_ray([1.0, 1.0, 0.3], ranges[keep], angles[keep], 3.0)
    np.testing.assert_array_equal(a.log_odds, b.log_odds)
    all_nan = grid_10cm()
    all_nan.insert_ray([1.0, 1.0, 0.0], [np.nan, np.nan], [0.0, 1.0], 3.0)
    assert np.all(all_nan.log_odds == 0)


@pytest.mark.parametrize(
    "pose, ranges, angles, max_range, match",
    [
        ([1, 1, 0], [0.5, -0.1], [0, 1], 3.0, "negative"),
        ([1, 1, 0], [0.5, 0.5], [0], 3.0, "differ in length"),
        ([1, 1], [0.5], [0], 3.0, "pose"),
        ([1, np.nan, 0], [0.5], [0], 3.0, "pose"),
        ([1, 1, 0], [0.5], [np.nan], 3.0, "angles"),
        ([1, 1, 0], [0.5], [0], 0.0, "max_range"),
        ([1, 1, 0], [0.5], [0], np.inf, "max_range"),
    ],
)
def test_bad_insert_ray_arguments_raise(pose, ranges, angles, max_range, match):
    grid = grid_10cm()
    with pytest.raises(ValueError, match=match):
        grid.insert_ray(pose, ranges, angles, max_range)
    assert np.all(grid.log_odds == 0)


@pytest.mark.parametrize("model", [(0.6, 0.7), (0.4, 0.4), (0.0, 0.7), (0.4, 1.0), (0.4,)])
def test_bad_inverse_model_raises(model):
    with pytest.raises(ValueError, match="inverse_model"):
        grid_10cm().insert_ray([1, 1, 0], [0.5], [0], 3.0, inverse_model=model)


def test_custom_inverse_model():
    grid = grid_10cm()
    grid.insert_ray([0.05, 0.05, 0.0], [0.35], [0.0], 3.0, inverse_model=(0.2, 0.9))
    np.testing.assert_allclose(grid.get_occupancy(np.vstack([cell_centre(0, 0), cell_centre(3, 0)])), [0.2, 0.9], atol=1e-6)


def test_log_odds_accumulate_across_scans_and_saturate():
    grid = grid_10cm()
    pts = np.vstack([cell_centre(0, 0), cell_centre(5, 0)])
    grid.insert_ray([0.05, 0.05, 0.0], [0.5], [0.0], 3.0)
    grid.insert_ray([0.05, 0.05, 0.0], [0.5], [0.0], 3.0)
    expected_occ = 1 / (1 + (0.3 / 0.7) ** 2)
    expected_free = 1 / (1 + (0.6 / 0.4) ** 2)
    np.testing.assert_allclose(grid.get_occupancy(pts), [expected_free, expected_occ], atol=1e-6)
    for _ in range(40):
        grid.insert_ray([0.05, 0.05, 0.0], [0.5], [0.0], 3.0)
    np.testing.assert_allclose(grid.get_occupancy(pts), [0.001, 0.999], atol=1e-6)
    assert grid.log_odds.min() >= np.log(0.001 / 0.999) - 1e-5


def test_check_occupancy_thresholds():
    grid = grid_10cm()
    end = cell_centre(5, 0)
    passed = cell_centre(0, 0)
    grid.insert_ray([0.05, 0.05, 0.0], [0.5], [0.0], 3.0)
    # 0.7 > 0.65 occupied; 0.4 is neither
    assert grid.check_occupancy(np.vstack([end, passed])).tolist() == [1, -1]
    expected = {2: -1, 3: -1, 4: 0}  # free probability after n passes: 0.31, 0.23, 0.16
    for n in (2, 3, 4):
        grid.insert_ray([0.05, 0.05, 0.0], [1.0], [0.0], 3.0)
        assert grid.check_occupancy(passed)[0] == expected[n]
    assert grid.check_occupancy([[-5.0, -5.0]]).tolist() == [-1]  # outside: unknown
    assert grid.get_occupancy([[-5.0, -5.0]]).tolist() == [0.5]
    ternary = grid.occupancy_matrix("ternary")
    assert ternary.dtype == np.int8 and set(np.unique(ternary)) <= {-1, 0, 1}


def test_custom_thresholds():
    grid = OccupancyGrid(1, 1, 10, occupied_threshold=0.75, free_threshold=0.45)
    grid.insert_ray([0.05, 0.05, 0.0], [0.5], [0.0], 3.0)
    assert grid.check_occupancy(np.vstack([cell_centre(5, 0), cell_centre(0, 0)])).tolist() == [-1, 0]
    with pytest.raises(ValueError, match="thresholds"):
        OccupancyGrid(1, 1, 10, occupied_threshold=0.3, free_threshold=0.6)


def test_one_update_per_cell_per_scan_occupied_wins():
    grid = grid_10cm()
    # two beams ending in the same cell: one occupied update
    grid.insert_ray([0.05, 0.05, 0.0], [0.52, 0.53], [0.0, 0.01], 3.0)
    np.testing.assert_allclose(grid.get_occupancy(cell_centre(5, 0)), P_OCC, atol=1e-6)
    # the start cell, crossed by both beams: one free update
    np.testing.assert_allclose(grid.get_occupancy(cell_centre(0, 0)), P_FREE, atol=1e-6)
    # a beam passing through another beam's end cell in the same scan leaves it occupied
    other = grid_10cm()
    other.insert_ray([0.05, 0.05, 0.0], [0.3, 0.9], [0.0, 0.0], 3.0)
    np.testing.assert_allclose(other.get_occupancy(np.vstack([cell_centre(3, 0), cell_centre(9, 0)])), P_OCC, atol=1e-6)


def test_insert_segments_matches_insert_ray():
    a, b = grid_10cm(), grid_10cm()
    angles = np.linspace(-2, 2, 15)
    ranges = np.linspace(0.2, 0.9, 15)
    a.insert_ray([1.0, 0.9, 0.2], ranges, angles, 3.0)
    ends = np.column_stack([1.0 + ranges * np.cos(angles + 0.2), 0.9 + ranges * np.sin(angles + 0.2)])
    b.insert_segments([1.0, 0.9], ends)
    np.testing.assert_array_equal(a.log_odds, b.log_odds)


def test_world2grid_conventions():
    grid = OccupancyGrid(3.0, 2.0, 10.0, grid_location_in_world=(-1.0, 5.0))
    assert grid.grid_size == (20, 30)
    assert grid.x_world_limits == pytest.approx((-1.0, 2.0)) and grid.y_world_limits == pytest.approx((5.0, 7.0))
    ij = grid.world2grid([[-1.0, 5.0], [-0.95, 6.99], [2.0, 7.0], [1.999, 5.001], [-1.0, 5.1]])
    # bottom-left corner -> last row; row 0 is the top; the outer top/right edges belong to the last cells
    assert ij.tolist() == [[19, 0], [0, 0], [0, 29], [19, 29], [18, 0]]
    assert grid.contains([[2.0, 7.0], [2.0001, 6.0], [-1.0, 4.9999]]).tolist() == [True, False, False]


def test_world_grid_round_trip():
    grid = OccupancyGrid(3.0, 2.0, 20.0, grid_location_in_world=(-1.3, 0.45))
    rows, cols = grid.grid_size
    ij = np.stack(np.meshgrid(np.arange(rows), np.arange(cols), indexing="ij"), -1).reshape(-1, 2)
    np.testing.assert_array_equal(grid.world2grid(grid.grid2world(ij)), ij)
    np.testing.assert_allclose(grid.grid2world(ij), grid.cell_centers().reshape(-1, 2))
    xy = np.random.default_rng(0).uniform([-1.3, 0.45], [1.7, 2.45], (1000, 2))
    back = grid.grid2world(grid.world2grid(xy))
    assert np.all(np.abs(back - xy) <= 0.5 / 20.0 + 1e-12)


def test_get_occupancy_in_grid_frame_and_bad_locations():
    grid = grid_10cm()
    grid.insert_ray([0.05, 1.95, 0.0], [0.25], [0.0], 3.0)
    np.testing.assert_allclose(grid.get_occupancy([[0, 2], [0, 0], [25, 0]], frame="grid"), [P_OCC, P_FREE, 0.5], atol=1e-6)
    with pytest.raises(ValueError, match="frame"):
        grid.get_occupancy([[0, 0]], frame="local")
    with pytest.raises(ValueError, match="integer"):
        grid.get_occupancy([[0.5, 0.0]], frame="grid")
    with pytest.raises(ValueError, match=r"\(N, 2\)"):
        grid.world2grid(np.zeros((3, 3)))


def test_growth_keeps_existing_cells_in_place():
    grid = grid_10cm()
    angles = np.linspace(0, 2 * np.pi, 40, endpoint=False)
    grid.insert_ray([1.0, 1.0, 0.0], np.full(40, 0.7), angles, 3.0)
    before = grid.occupancy_matrix()
    centres = grid.cell_centers().reshape(-1, 2)
    old_shape = grid.grid_size
    # beams leaving the grid on the left and the top
    grid.insert_ray([0.5, 1.5, 0.0], [2.0, 1.5], [np.pi, np.pi / 2], 3.0)
    rows, cols = grid.grid_size
    assert rows > old_shape[0] and cols > old_shape[1]
    assert (rows - old_shape[0]) % GROW_STEP_CELLS == 0 and (cols - old_shape[1]) % GROW_STEP_CELLS == 0
    x0, y0 = grid.grid_location_in_world
    assert x0 <= -1.5 and y0 == pytest.approx(0.0)
    assert grid.y_world_limits[1] >= 3.0
    after = grid.get_occupancy(centres).reshape(before.shape)
    changed = ~np.isclose(after, before, atol=1e-6)
    # only cells on the two new beams changed
    assert changed.sum() <= 30
    np.testing.assert_allclose(grid.get_occupancy([[-1.45, 1.55], [0.55, 2.95]]), P_OCC, atol=1e-6)
    np.testing.assert_allclose(grid.get_occupancy([[-0.5, 1.55]]), P_FREE, atol=1e-6)
    # the same world point maps to the same cell value whatever the growth
    np.testing.assert_allclose(grid.get_occupancy([[1.7, 1.0]]), before[10, 17], atol=1e-6)


def test_grow_to_include():
    grid = grid_10cm()
    grid.grow_to_include([[5.0, -3.0]])
    assert grid.contains([[5.0, -3.0], [0.0, 0.0], [2.0, 2.0]]).all()
    assert np.all(grid.log_odds == 0)
    size = grid.grid_size
    grid.grow_to_include([[1.0, 1.0]])
    assert grid.grid_size == size
    with pytest.raises(ValueError, match="finite"):
        grid.grow_to_include([[np.inf, 0.0]])


def test_from_probabilities_and_copy():
    p = np.array([[0.9, 0.5], [0.1, 0.0]])
    grid = OccupancyGrid.from_probabilities(p, 10.0, (1.0, 2.0))
    assert grid.occupancy_matrix("ternary").tolist() == [[1, -1], [0, 0]]
    np.testing.assert_allclose(grid.occupancy_matrix(), [[0.9, 0.5], [0.1, 0.001]], atol=1e-6)
    clone = grid.copy()
    clone.insert_ray([1.05, 2.05, 0.0], [0.1], [0.0], 1.0)
    assert not np.array_equal(clone.log_odds, grid.log_odds)
    with pytest.raises(ValueError):
        OccupancyGrid.from_probabilities(np.array([[1.5]]), 10.0)


@pytest.mark.parametrize("args", [(0, 1, 10), (1, 1, 0), (1, 1, np.nan), (1, -2, 10)])
def test_bad_geometry_raises(args):
    with pytest.raises(ValueError):
        OccupancyGrid(*args)


def test_log_odds_view_is_read_only():
    grid = grid_10cm()
    with pytest.raises(ValueError):
        grid.log_odds[0, 0] = 1.0


def test_cropped_keeps_cells_in_place_and_drops_unknown_margin() -> None:
    grid = OccupancyGrid(10.0, 8.0, 20, (-5.0, -4.0))
    grid.insert_ray((1.0, 0.5, 0.0), np.array([1.0, 2.0]), np.array([0.0, np.pi / 2]), 5.0)
    small = grid.cropped(margin_cells=3)
    assert small.grid_size[0] < grid.grid_size[0] and small.grid_size[1] < grid.grid_size[1]
    probe = np.array([[2.0, 0.5], [1.0, 2.5], [1.0, 1.0], [1.5, 0.5]])
    np.testing.assert_array_equal(small.get_occupancy(probe), grid.get_occupancy(probe))
    observed = grid.log_odds != 0
    assert int((small.log_odds != 0).sum()) == int(observed.sum())
    rows, cols = np.nonzero(small.log_odds != 0)
    assert rows.min() == 3 and cols.min() == 3
    assert rows.max() == small.grid_size[0] - 4 and cols.max() == small.grid_size[1] - 4


def test_minus_infinity_ranges_are_ignored_like_nan() -> None:
    """REP 117: -inf means an object closer than range_min; it tells nothing about any cell."""
    from bagtools.grid import OccupancyGrid

    a, b = OccupancyGrid(4, 4, 20), OccupancyGrid(4, 4, 20)
    angles = np.array([0.0, 0.5, 1.0])
    a.insert_ray([1.0, 1.0, 0.0], np.array([1.0, -np.inf, 1.5]), angles, 3.0)
    b.insert_ray([1.0, 1.0, 0.0], np.array([1.0, np.nan, 1.5]), angles, 3.0)
    np.testing.assert_array_equal(a.occupancy_matrix(), b.occupancy_matrix())
