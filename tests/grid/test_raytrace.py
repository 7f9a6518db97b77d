"""Exact traversal against a brute-force reference: random beams, axis-aligned, through corners."""

from __future__ import annotations

import numpy as np
import pytest

from bagtools.grid.raytrace import EPS_CELLS, traverse, unique_per_segment

TOL_LENGTH = 1e-7  # the reference counts a cell when the segment runs more than this inside it


def reference_cells(p0: np.ndarray, p1: np.ndarray) -> set[tuple[int, int]]:
    """Cells the segment runs through for a positive length, by clipping it against every
    cell box near it (slab test). An axis the segment does not move along (within EPS)
    uses the floor convention for its fixed coordinate."""
    d = p1 - p0
    length = float(np.hypot(*d))
    lo = np.floor(np.minimum(p0, p1)).astype(int) - 1
    hi = np.floor(np.maximum(p0, p1)).astype(int) + 1
    cells = set()
    for i in range(lo[0], hi[0] + 1):
        for j in range(lo[1], hi[1] + 1):
            t0, t1, inside = 0.0, 1.0, True
            for axis, (a, b) in enumerate(((i, i + 1), (j, j + 1))):
                if abs(d[axis]) <= EPS_CELLS:
                    inside &= a <= p0[axis] < b
                else:
                    ta, tb = (a - p0[axis]) / d[axis], (b - p0[axis]) / d[axis]
                    t0, t1 = max(t0, min(ta, tb)), min(t1, max(ta, tb))
            if inside and (t1 - t0) * length > TOL_LENGTH:
                cells.add((i, j))
    if length <= TOL_LENGTH:
        cells = {(int(np.floor(p0[0])), int(np.floor(p0[1])))}
    return cells


def cells_by_segment(start: np.ndarray, ends: np.ndarray) -> list[set[tuple[int, int]]]:
    trav = unique_per_segment(traverse(start, ends, with_segment=True))
    out: list[set[tuple[int, int]]] = [set() for _ in range(len(ends))]
    for s, c, r in zip(trav.segment.tolist(), trav.cols.tolist(), trav.rows.tolist()):
        out[s].add((c, r))
    return out


def check_against_reference(start: np.ndarray, ends: np.ndarray) -> None:
    got = cells_by_segment(start, ends)
    trav = traverse(start, ends)
    for k, end in enumerate(ends):
        ref = reference_cells(np.asarray(start, float), end)
        assert got[k] == ref, (start, end, sorted(got[k] ^ ref))
        # the end cell is the last visited cell: one of the segment's cells, containing the end's neighbourhood
        assert (trav.end_cols[k], trav.end_rows[k]) in ref


def test_random_segments_match_reference():
    rng = np.random.default_rng(7)
    for _ in range(60):
        start = rng.uniform(-6, 6, 2)
        ends = start + rng.uniform(-9, 9, (12, 2))
        check_against_reference(start, ends)


def test_random_segments_from_integer_and_half_points():
    rng = np.random.default_rng(8)
    for start in ([0.0, 0.0], [2.0, -3.0], [0.5, 0.5], [1.0, 0.5], [0.5, -2.0]):
        ends = np.asarray(start) + rng.integers(-6, 7, (25, 2)) * rng.choice([0.5, 1.0, 0.25], (25, 1))
        check_against_reference(np.asarray(start), ends)


@pytest.mark.parametrize("start", [(0.5, 0.5), (0.0, 0.0), (1.0, 0.5), (0.5, 2.0), (0.25, 0.75), (-3.0, 2.0)])
def test_every_15_degrees_including_axes_and_diagonals(start):
    start = np.asarray(start)
    angles = np.deg2rad(np.arange(0, 360, 15))
    for r in (0.3, 1.0, 2.5, 4 * np.sqrt(2), 7.0):
        ends = start + r * np.column_stack([np.cos(angles), np.sin(angles)])
        check_against_reference(start, ends)


def test_exact_diagonal_skips_cells_touching_only_at_corners():
    cells = cells_by_segment(np.array([0.5, 0.5]), np.array([[3.5, 3.5], [-2.5, 3.5]]))
    assert cells[0] == {(0, 0), (1, 1), (2, 2), (3, 3)}
    assert cells[1] == {(0, 0), (-1, 1), (-2, 2), (-3, 3)}


def test_axis_aligned_beams_stay_in_one_row_or_column():
    cells = cells_by_segment(np.array([0.5, 0.5]), np.array([[4.5, 0.5], [0.5, -3.5], [-2.0, 0.5]]))
    assert cells[0] == {(c, 0) for c in range(5)}
    assert cells[1] == {(0, r) for r in range(-4, 1)}
    # ending exactly on a grid line: the end cell is the one the beam arrives from
    assert cells[2] == {(0, 0), (-1, 0), (-2, 0)}


def test_beam_along_a_grid_line_uses_the_cell_above_and_right():
    cells = cells_by_segment(np.array([0.0, 1.0]), np.array([[3.0, 1.0], [0.0, 4.0]]))
    assert cells[0] == {(0, 1), (1, 1), (2, 1)}
    assert cells[1] == {(0, 1), (0, 2), (0, 3)}


def test_zero_length_and_in_cell_segments_visit_the_start_cell():
    trav = traverse(np.array([2.3, -1.7]), np.array([[2.3, -1.7], [2.9, -1.1]]))
    assert set(zip(trav.cols.tolist(), trav.rows.tolist())) == {(2, -2)}
    assert trav.end_cols.tolist() == [2, 2] and trav.end_rows.tolist() == [-2, -2]


def test_cell_count_is_one_plus_lines_crossed():
    rng = np.random.default_rng(3)
    start = np.array([10.37, -4.81])
    ends = start + rng.uniform(-40, 40, (500, 2))
    trav = traverse(start, ends, with_segment=True)
    lines = np.abs(np.floor(ends) - np.floor(start)).sum(axis=1)
    counts = np.bincount(trav.segment, minlength=len(ends))
    assert np.array_equal(counts, 1 + lines)  # generic beams cross no lattice corner exactly


def test_per_segment_starts():
    starts = np.array([[0.5, 0.5], [3.5, 3.5]])
    ends = np.array([[2.5, 0.5], [3.5, 1.5]])
    cells = unique_per_segment(traverse(starts, ends, with_segment=True))
    got = sorted(zip(cells.segment.tolist(), cells.cols.tolist(), cells.rows.tolist()))
    assert got == [(0, 0, 0), (0, 1, 0), (0, 2, 0), (1, 3, 1), (1, 3, 2), (1, 3, 3)]


def test_unique_per_segment_needs_segment_ids():
    with pytest.raises(ValueError, match="with_segment"):
        unique_per_segment(traverse(np.zeros(2), np.ones((1, 2))))
