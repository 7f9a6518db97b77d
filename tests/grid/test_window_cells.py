"""window_cells (insert_ray's traversal into flat window indices) visits exactly traverse's cells, in both layouts."""

from __future__ import annotations

import numpy as np
import pytest

from bagtools.grid import OccupancyGrid
from bagtools.grid import raytrace
from bagtools.grid.raytrace import Workspace, segment_batch, traverse, window_cells


def random_batches(seed: int):
    """Starts on and off grid lines, ends rounded to halves/quarters (corner crossings) or not, some zero length."""
    rng = np.random.default_rng(seed)
    for _ in range(40):
        start = rng.integers(-8, 8, 2) / rng.choice([1, 2, 4, 3.7])
        n = int(rng.integers(1, 60))
        ends = start + rng.uniform(-12, 12, (n, 2)) * rng.choice([0.05, 1.0], (n, 1))
        ends = np.round(ends * 4) / 4 if rng.random() < 0.5 else ends
        ends[rng.random(n) < 0.1] = start
        yield start, ends


def cell_set(cols: np.ndarray, rows: np.ndarray, col0: int, row0: int, width: int) -> set[int]:
    return set(((rows - row0) * width + (cols - col0)).tolist())


@pytest.mark.parametrize("layout", ["padded", "compact"])
def test_window_cells_are_traverse_cells(monkeypatch, layout):
    if layout == "compact":
        monkeypatch.setattr(raytrace, "PADDED_PER_CROSSING", -1e12)
    work = Workspace()
    for start, ends in random_batches(11):
        trav = traverse(start, ends)
        col0, row0 = int(trav.cols.min()) - 3, int(trav.rows.min()) - 2
        width, height = int(trav.cols.max()) - col0 + 5, int(trav.rows.max()) - row0 + 1
        flat = window_cells(segment_batch(start, ends.T), col0, row0, width, height, work)
        assert flat.dtype == np.int64 and 0 <= flat.min() and flat.max() < width * height
        assert set(flat.tolist()) == cell_set(trav.cols, trav.rows, col0, row0, width)


def test_far_from_the_origin_the_cells_are_listed_exactly():
    start = np.array([2.0**47 + 0.25, -(2.0**46) + 0.5])
    ends = start + np.random.default_rng(2).uniform(-20, 20, (30, 2))
    trav = traverse(start, ends)
    col0, row0 = int(trav.cols.min()), int(trav.rows.min())
    width, height = int(trav.cols.max()) - col0 + 1, int(trav.rows.max()) - row0 + 1
    flat = window_cells(segment_batch(start, ends.T), col0, row0, width, height)
    assert set(flat.tolist()) == cell_set(trav.cols, trav.rows, col0, row0, width)


def test_both_layouts_give_the_same_map(monkeypatch):
    rng = np.random.default_rng(4)
    angles = np.linspace(-np.pi, np.pi, 270, endpoint=False)
    poses = np.column_stack([rng.integers(-40, 40, (25, 2)) / 8.0, rng.choice([0.0, np.pi / 2, 0.3], 25)])
    ranges = rng.uniform(0.0, 6.0, (25, angles.size))
    ranges[rng.random(ranges.shape) < 0.2] = np.inf
    grids = []
    for allowance in (raytrace.PADDED_PER_CROSSING, -1e12):
        monkeypatch.setattr(raytrace, "PADDED_PER_CROSSING", allowance)
        grid = OccupancyGrid(1.0, 1.0, 20.0, (-0.5, -0.5))
        for pose, scan in zip(poses, ranges):
            grid.insert_ray(pose, scan, angles, 5.0)
        grids.append(grid)
    assert np.array_equal(grids[0].log_odds, grids[1].log_odds)
    assert np.count_nonzero(grids[0].log_odds) > 1000
