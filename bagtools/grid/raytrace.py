"""Exact grid traversal of many 2-D segments at once (Amanatides-Woo, vectorized).

Coordinates here are *grid units*: a point (u, v) lies in cell (col, row) =
(floor(u), floor(v)); cell (i, j) covers u in [i, i+1) and v in [j, j+1), rows
counting upwards (the occupancy grid flips them into image order).

A segment's cells are the cells its pieces lie in: cut the segment at every
vertical (u integer) and horizontal (v integer) grid line it crosses; each piece
of positive length lies in exactly one cell. This is every cell whose interior
the segment passes through; a segment through a lattice corner does not visit
the two cells that only touch the corner, and one running exactly along a grid
line is assigned to the cell above / to the right of it, as the floor convention
does for points. Pieces shorter than :data:`EPS_CELLS` (a segment grazing a
corner by less than a nanometre-scale margin) are ignored, so rounding near
corners never produces stray cells.

Instead of stepping cell by cell, every crossing of every segment is computed
at once: crossing k of the vertical lines enters column ``c0 + k*step_u`` at a
height that is linear in k, and likewise for the horizontal lines. The cell
entered at each crossing, together with the start cell, is the whole sequence.
Work is proportional to the number of cells visited, with no Python loop per
segment or per cell.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

EPS_CELLS = 1e-9
"""Pieces of a segment shorter than this (in cells) are ignored near grid lines."""


class Traversal(NamedTuple):
    """Cells visited by a batch of segments (grid units, rows counting upwards).

    ``cols``/``rows`` list every visited cell of every segment, starting with the
    N start cells (entry s is segment s's first cell); a cell where a segment
    crosses a lattice corner exactly may appear twice for that segment (callers
    that count a cell once per segment use :func:`unique_per_segment`).
    ``segment`` gives the segment index of each entry when it was requested
    (otherwise None). ``end_cols``/``end_rows`` are the cell each segment ends
    in (the cell of its last piece), one per segment.
    """

    cols: np.ndarray
    rows: np.ndarray
    segment: np.ndarray | None
    end_cols: np.ndarray
    end_rows: np.ndarray


def _axis_crossings(
    a0: np.ndarray, a_first_cell: np.ndarray, n_cross: np.ndarray, step: np.ndarray,
    b0: np.ndarray, slope: np.ndarray, b_bias: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Cells entered at each crossing of the grid lines across axis ``a``.

    For segment s, crossing k = 1..n_cross[s] enters a-cell ``a_first_cell + k*step``
    through the line a = a_first_cell + (step < 0) + k*step; the b-coordinate there is
    ``b0 + (line - a0)*slope`` and the b-cell is its floor after nudging by ``b_bias``
    (a tiny step in the direction of travel, so that a crossing exactly on a lattice
    corner lands in the cell the segment continues into). Returns (a_cells, b_cells)
    as float arrays of length n_cross.sum(), segment by segment.
    """
    total = int(n_cross.sum())
    offsets = np.cumsum(n_cross) - n_cross
    back = (step < 0).astype(np.float64)
    # per segment: k = e + (1 - offset) for global entry index e; exact in float64
    coeffs = np.stack([
        1.0 - offsets,
        a_first_cell,
        step,
        b0 + b_bias + (a_first_cell + back - a0) * slope,
        step * slope,
    ])
    per_entry = np.repeat(coeffs, n_cross, axis=1)
    k = np.arange(total, dtype=np.float64)
    k += per_entry[0]
    a_cells = per_entry[2] * k
    a_cells += per_entry[1]
    b_cells = per_entry[4] * k
    b_cells += per_entry[3]
    np.floor(b_cells, out=b_cells)
    return a_cells, b_cells


def traverse(start_uv: np.ndarray, ends_uv: np.ndarray, with_segment: bool = False) -> Traversal:
    """Every cell each segment from ``start_uv`` to ``ends_uv[s]`` passes through.

    Args:
        start_uv: (2,) common start point, or (N, 2) one start per segment, grid units.
        ends_uv: (N, 2) end points, grid units (finite).
        with_segment: also return the segment index of each visited cell.

    Returns:
        A :class:`Traversal` with integer (int64) cell indices.
    """
    ends_uv = np.asarray(ends_uv, dtype=np.float64).reshape(-1, 2)
    n = ends_uv.shape[0]
    start_uv = np.broadcast_to(np.asarray(start_uv, dtype=np.float64), (n, 2))
    u0, v0 = start_uv[:, 0], start_uv[:, 1]
    ue, ve = ends_uv[:, 0], ends_uv[:, 1]
    du, dv = ue - u0, ve - v0
    # direction of travel per axis; an extent below EPS counts as none (no crossings)
    su = np.where(np.abs(du) > EPS_CELLS, np.sign(du), 0.0)
    sv = np.where(np.abs(dv) > EPS_CELLS, np.sign(dv), 0.0)
    # first and last piece: nudge into the segment so boundary points go to the visited cell
    c0 = np.floor(u0 + su * EPS_CELLS)
    r0 = np.floor(v0 + sv * EPS_CELLS)
    nu_f = np.maximum((np.floor(ue - su * EPS_CELLS) - c0) * su, 0.0)
    nv_f = np.maximum((np.floor(ve - sv * EPS_CELLS) - r0) * sv, 0.0)
    ce = c0 + su * nu_f
    re = r0 + sv * nv_f
    nu = nu_f.astype(np.int64)
    nv = nv_f.astype(np.int64)
    with np.errstate(divide="ignore", invalid="ignore"):
        # an axis without travel keeps its start coordinate along the whole segment
        slope_vu = np.where((su != 0.0) & (sv != 0.0), dv / du, 0.0)
        slope_uv = np.where((su != 0.0) & (sv != 0.0), du / dv, 0.0)
    # crossings of vertical lines: enter columns, rows from v
    cu_cols, cu_rows = _axis_crossings(u0, c0, nu, su, v0, slope_vu, sv * EPS_CELLS)
    # crossings of horizontal lines: enter rows, columns from u
    cv_rows, cv_cols = _axis_crossings(v0, r0, nv, sv, u0, slope_uv, su * EPS_CELLS)
    cols = np.concatenate([c0, cu_cols, cv_cols]).astype(np.int64)
    rows = np.concatenate([r0, cu_rows, cv_rows]).astype(np.int64)
    segment = None
    if with_segment:
        ids = np.arange(n)
        segment = np.concatenate([ids, np.repeat(ids, nu), np.repeat(ids, nv)])
    return Traversal(cols, rows, segment, ce.astype(np.int64), re.astype(np.int64))


def unique_per_segment(trav: Traversal) -> Traversal:
    """The same traversal with each (segment, cell) pair listed once, sorted by segment.

    Needs a traversal made with ``with_segment=True``.
    """
    if trav.segment is None:
        raise ValueError("unique_per_segment needs a traversal made with with_segment=True")
    keys = np.stack([trav.segment, trav.cols, trav.rows], axis=1)
    uniq = np.unique(keys, axis=0)
    return Traversal(uniq[:, 1], uniq[:, 2], uniq[:, 0], trav.end_cols, trav.end_rows)
