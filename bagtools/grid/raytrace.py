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

:func:`traverse` lists the crossings segment by segment. :func:`window_cells`, behind
``OccupancyGrid.insert_ray``, needs only the set of cells in a window: it evaluates the
same formulas (the same floating-point operations, so the same cells) over a padded
(axis, crossing number, segment) block, which needs no per-crossing gather.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

EPS_CELLS = 1e-9
"""Pieces of a segment shorter than this (in cells) are ignored near grid lines."""

PADDED_PER_CROSSING = 4.0
""":func:`window_cells` lays crossings out as a padded block while it holds at most this many
entries per crossing (plus 65536): its work arrays stay within a few times the crossings."""


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


class SegmentBatch(NamedTuple):
    """Per-segment traversal set-up, one row per axis: row 0 is u (columns), row 1 is v (rows).

    All arrays are (2, N) float64 in grid units. For axis a and crossing k = 1..n_cross[a, s],
    segment s enters a-cell ``first[a, s] + k*step[a, s]`` and the other axis' cell
    ``floor(b_first[a, s] + b_step[a, s]*k)``.
    """

    first: np.ndarray  # start cell (nudged into the segment)
    step: np.ndarray  # direction of travel: -1, 0 (extent below EPS_CELLS) or +1
    n_cross: np.ndarray  # grid lines crossed (whole numbers)
    last: np.ndarray  # end cell (the cell of the last piece)
    b_first: np.ndarray  # other coordinate at line k = 0, nudged by EPS_CELLS in its direction of travel
    b_step: np.ndarray  # other coordinate's change per line crossed


def segment_batch(start_uv: np.ndarray, ends_uv: np.ndarray) -> SegmentBatch:
    """Set up the traversal of segments from ``start_uv`` ((2,) or (2, N)) to ``ends_uv`` ((2, N)), grid units."""
    p0 = start_uv if start_uv.ndim == 2 else start_uv[:, None]
    d = ends_uv - p0
    # direction of travel per axis; an extent below EPS counts as none (no crossings)
    step = np.where(np.abs(d) > EPS_CELLS, np.sign(d), 0.0)
    # first and last piece: nudge into the segment so boundary points go to the visited cell
    nudge = step * EPS_CELLS
    first = np.floor(p0 + nudge)
    n_cross = np.maximum((np.floor(ends_uv - nudge) - first) * step, 0.0)
    last = first + step * n_cross
    # an axis without travel keeps its start coordinate along the whole segment
    moving = (step[0] != 0.0) & (step[1] != 0.0)
    slope = np.divide(d[::-1], d, out=np.zeros_like(d), where=moving)
    # crossing k of the lines across axis a is line first + (step < 0) + k*step
    b_first = p0[::-1] + nudge[::-1] + (first + (step < 0) - p0) * slope
    return SegmentBatch(first, step, n_cross, last, b_first, step * slope)


def _compact_k(n_cross: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(k, owner): crossing number 1..n and segment index of every crossing, segment by segment."""
    counts = n_cross.astype(np.int64)
    owner = np.repeat(np.arange(counts.size), counts)
    k = np.arange(owner.size, dtype=np.float64)
    k += np.repeat(1.0 - (np.cumsum(counts) - counts), counts)  # exact in float64
    return k, owner


def _b_cells(k: np.ndarray, b_first: np.ndarray, b_step: np.ndarray) -> np.ndarray:
    """floor(b_first + b_step*k), float64, computed in place of a new array."""
    b = b_step * k
    b += b_first
    return np.floor(b, out=b)


def _listed_cells(seg: SegmentBatch, with_segment: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """(cols, rows, segment): the N start cells, then every crossing segment by segment (float64 cells)."""
    n = seg.first.shape[1]
    cells: list[list[np.ndarray]] = [[seg.first[0]], [seg.first[1]]]  # [cols, rows]
    ids = [np.arange(n)]
    for a in (0, 1):  # crossings of vertical lines enter columns, of horizontal lines rows
        k, owner = _compact_k(seg.n_cross[a])
        cells[a].append(seg.step[a, owner] * k + seg.first[a, owner])
        cells[1 - a].append(_b_cells(k, seg.b_first[a, owner], seg.b_step[a, owner]))
        ids.append(owner)
    segment = np.concatenate(ids) if with_segment else None
    return np.concatenate(cells[0]), np.concatenate(cells[1]), segment


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
    start_uv = np.asarray(start_uv, dtype=np.float64)
    start_uv = start_uv.reshape(2) if start_uv.size == 2 and start_uv.ndim < 2 else start_uv.reshape(-1, 2).T
    seg = segment_batch(start_uv, ends_uv.T)
    cols, rows, segment = _listed_cells(seg, with_segment)
    return Traversal(cols.astype(np.int64), rows.astype(np.int64), segment,
                     seg.last[0].astype(np.int64), seg.last[1].astype(np.int64))


_ROUNDING = 1.5 * 2.0**52
"""A whole number x with |x| < 2**51 is stored exactly in _ROUNDING + x, whose bits are _ROUNDING_BITS + x."""
_ROUNDING_BITS = int(np.float64(_ROUNDING).view(np.int64))


class Workspace:
    """Work arrays kept from one call to the next, so that a stream of similar scans does not
    allocate (and page-fault in) fresh arrays each time; arrays of more than ``keep_entries``
    entries are made afresh and not kept."""

    def __init__(self, keep_entries: int = 1 << 18) -> None:
        self.keep_entries = keep_entries
        self._arrays: dict[str, np.ndarray] = {}

    def array(self, name: str, size: int, dtype: type) -> np.ndarray:
        """A 1-D array of ``size`` entries (contents undefined), valid until the next request of ``name``."""
        buf = self._arrays.get(name)
        if buf is not None and buf.size >= size and buf.dtype == dtype:
            return buf[:size]
        buf = np.empty(size, dtype)
        if size <= self.keep_entries:
            self._arrays[name] = buf
        return buf

    def crossing_numbers(self, k_max: int, n: int) -> np.ndarray:
        """(k_max, n) float64 view with entry [k - 1, s] = k, from a table kept (and grown) between calls."""
        table = self._arrays.get("crossing_numbers")
        if table is None or table.shape[0] < k_max or table.shape[1] < n:
            shape = (k_max, n) if table is None else (max(k_max, table.shape[0]), max(n, table.shape[1]))
            table = np.empty(shape)
            table[...] = np.arange(1.0, shape[0] + 1.0)[:, None]
            if table.size <= self.keep_entries:
                self._arrays["crossing_numbers"] = table
        return table[:k_max, :n]


def window_cells(
    seg: SegmentBatch, col0: int, row0: int, width: int, height: int, work: Workspace | None = None,
) -> np.ndarray:
    """Flat indices ``(row - row0)*width + (col - col0)`` of every cell the segments visit (repeats included).

    The visited cells must lie in the window of ``height`` x ``width`` cells at (col0, row0).
    Crossings are laid out as a (2, K, N) block, K the most lines any segment crosses on one
    axis, with each segment's crossing numbers past its own count held at its last crossing (a
    segment crossing nothing on an axis repeats its start cell), so that no per-crossing gather
    is needed. When that block would hold more than :data:`PADDED_PER_CROSSING` entries per
    crossing (very unequal segment lengths), or cell numbers could leave float64's exact
    whole numbers, the crossings are listed segment by segment instead. Returns int64
    indices, possibly a view into ``work``'s arrays (valid until its next use).
    """
    n = seg.first.shape[1]
    k_max = int(seg.n_cross.max()) if n else 0
    padded = 2 * n * k_max
    exact = (abs(col0) + abs(row0) + width + height) * (width + 1) < 2**50
    if not (exact and padded <= PADDED_PER_CROSSING * float(seg.n_cross.sum()) + 65536):
        cols, rows, _ = _listed_cells(seg, False)
        flat = rows.astype(np.int64) - row0
        flat *= width
        flat += cols.astype(np.int64)
        flat -= col0
        return flat
    work = work if work is not None else Workspace(0)
    weight = np.array([[1.0], [float(width)]])  # (col, row) -> flat index
    origin = np.array([[float(col0)], [float(row0)]])
    from_origin = (seg.first - origin) * weight
    # axis a: flat = floor(b_first + b_step*k)*weight_b + a_offset + a_step*k, all whole numbers;
    # each is summed onto _ROUNDING, exactly, so that one integer subtraction of the bits makes it an index
    a_offset = from_origin - origin[::-1] * weight[::-1] + _ROUNDING
    flat = work.array("flat", n + padded, np.float64)
    k = work.array("k", padded, np.float64).reshape(2, k_max, n)
    b = flat[n:].reshape(2, k_max, n)
    np.minimum(work.crossing_numbers(k_max, n), seg.n_cross[:, None, :], out=k)
    np.multiply(seg.b_step[:, None, :], k, out=b)
    b += np.where(seg.n_cross > 0, seg.b_first, seg.first[::-1])[:, None, :]  # at k = 0: the start cell
    np.floor(b, out=b)
    b[0] *= weight[1, 0]
    k *= (seg.step * weight)[:, None, :]
    k += a_offset[:, None, :]
    b += k
    np.add(from_origin.sum(axis=0), _ROUNDING, out=flat[:n])  # the start cells
    out = flat.view(np.int64)
    out -= _ROUNDING_BITS
    return out


def unique_per_segment(trav: Traversal) -> Traversal:
    """The same traversal with each (segment, cell) pair listed once, sorted by segment.

    Needs a traversal made with ``with_segment=True``.
    """
    if trav.segment is None:
        raise ValueError("unique_per_segment needs a traversal made with with_segment=True")
    keys = np.stack([trav.segment, trav.cols, trav.rows], axis=1)
    uniq = np.unique(keys, axis=0)
    return Traversal(uniq[:, 1], uniq[:, 2], uniq[:, 0], trav.end_cols, trav.end_rows)
