"""Map scoring on toy maps, truth rasterization, and an end-to-end map of a square room."""

from __future__ import annotations

import json

import numpy as np
import pytest

from bagtools.grid import OccupancyGrid, rasterize_truth, score_map


def ring(shape=(12, 12), lo=2, hi=9) -> np.ndarray:
    occ = np.zeros(shape, dtype=bool)
    occ[lo, lo:hi + 1] = occ[hi, lo:hi + 1] = occ[lo:hi + 1, lo] = occ[lo:hi + 1, hi] = True
    return occ


def interior(shape=(12, 12), lo=2, hi=9) -> np.ndarray:
    free = np.zeros(shape, dtype=bool)
    free[lo + 1:hi, lo + 1:hi] = True
    return free


def as_map(occupied: np.ndarray, free: np.ndarray) -> np.ndarray:
    out = np.full(occupied.shape, -1, dtype=np.int8)
    out[free] = 0
    out[occupied] = 1
    return out


def test_perfect_map_scores_one():
    score = score_map(as_map(ring(), interior()), ring(), interior())
    assert (score.occupied_precision, score.occupied_recall, score.free_share, score.free_marked_occupied) == (1, 1, 1, 0)
    assert score.true_occupied_cells == 28 and score.true_free_cells == 36


def test_one_cell_shift_is_within_tolerance_only():
    shifted = np.roll(ring(), 1, axis=1)
    within = score_map(as_map(shifted, np.zeros_like(shifted)), ring(), interior())
    assert within.occupied_precision == 1 and within.occupied_recall == 1 and within.free_share == 0
    strict = score_map(as_map(shifted, np.zeros_like(shifted)), ring(), interior(), tolerance_cells=0)
    assert strict.occupied_precision == pytest.approx(14 / 28) and strict.occupied_recall == pytest.approx(14 / 28)


def test_phantom_obstacles_and_missing_walls():
    occ = ring().copy()
    occ[5, 5] = True          # phantom in the middle of the room
    occ[2, 2:10] = False      # the top wall missed (8 cells)
    free = interior().copy()
    free[6:, :] = False       # lower half of the room not observed
    score = score_map(as_map(occ, free), ring(), interior())
    assert score.map_occupied_cells == 21
    assert score.occupied_precision == pytest.approx(20 / 21)
    # of the missed top wall, the two cells at each end are within one cell of a side wall
    assert score.occupied_recall == pytest.approx((28 - 4) / 28)
    assert score.free_share == pytest.approx(17 / 36)  # 18 observed, one of them the phantom
    assert score.free_marked_occupied == pytest.approx(1 / 36)
    assert json.loads(json.dumps(score.to_dict()))["tolerance_cells"] == 1


def test_empty_denominators_are_nan_and_bad_shapes_raise():
    empty = np.zeros((4, 4), dtype=bool)
    score = score_map(np.full((4, 4), -1), empty, empty)
    assert np.isnan(score.occupied_precision) and np.isnan(score.free_share)
    assert score.to_dict()["occupied_recall"] is None
    with pytest.raises(ValueError, match="one shape"):
        score_map(np.zeros((4, 4)), np.zeros((4, 5), bool), empty)
    with pytest.raises(ValueError, match="tolerance"):
        score_map(np.zeros((4, 4)), empty, empty, tolerance_cells=-1)


HALF = 2.0  # the room is [-2, 2] x [-2, 2] metres


def room_surface_distance(xy: np.ndarray) -> np.ndarray:
    inside = HALF - np.abs(xy)
    outside = np.hypot(*np.maximum(-inside, 0.0).T)
    return np.where(np.all(inside >= 0, axis=1), inside.min(axis=1), outside)


def room_clearance(xy: np.ndarray) -> np.ndarray:
    return (HALF - np.abs(xy)).min(axis=1)


def room_ranges(pose: np.ndarray, angles: np.ndarray) -> np.ndarray:
    d = np.column_stack([np.cos(angles + pose[2]), np.sin(angles + pose[2])])
    with np.errstate(divide="ignore"):
        t = np.where(d > 0, (HALF - pose[:2]) / d, np.where(d < 0, (-HALF - pose[:2]) / d, np.inf))
    return t.min(axis=1)


def test_rasterize_truth_of_the_room():
    grid = OccupancyGrid(5.0, 5.0, 10.0, (-2.5, -2.5))
    occupied, free = rasterize_truth(grid, room_surface_distance, room_clearance)
    assert occupied.shape == free.shape == grid.grid_size
    assert not np.any(occupied & free)
    # walls at x = +-2 run along cell edges: the two columns beside each wall
    assert occupied[10, [4, 5, 44, 45]].all() and not occupied[10, [3, 6, 43, 46]].any()
    assert free[10, 6:44].all() and not free[10, :6].any()


def test_mapping_the_room_scores_well():
    grid = OccupancyGrid(5.0, 5.0, 20.0, (-2.5, -2.5))
    angles = np.linspace(0, 2 * np.pi, 360, endpoint=False)
    rng = np.random.default_rng(2)
    for k in range(30):
        pose = np.r_[rng.uniform(-1.5, 1.5, 2), rng.uniform(-np.pi, np.pi)]
        ranges = room_ranges(pose, angles) + rng.normal(0, 0.01, 360)
        ranges[rng.random(360) < 0.05] = np.nan
        grid.insert_ray(pose, ranges, angles, max_range=3.5)
    occupied, free = rasterize_truth(grid, room_surface_distance, room_clearance)
    score = score_map(grid.occupancy_matrix("ternary"), occupied, free)
    assert score.occupied_precision > 0.97
    assert score.occupied_recall > 0.95
    assert score.free_share > 0.95
    assert score.free_marked_occupied < 0.005
