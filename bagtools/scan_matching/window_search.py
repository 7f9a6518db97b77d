"""The search of :mod:`bagtools.scan_matching.correlative` over its discretized window: the window itself (the
candidate headings and the current points rotated and binned once per heading), the multi-resolution branch and
bound (W. Hess et al., ICRA 2016) and the exhaustive search it must agree with bit for bit, every candidate above a
score (for the distinct peaks of a window), and Olson's covariance around the best. The module docstring of
:mod:`~bagtools.scan_matching.correlative` describes the method; this module holds its inner loops.

Scores are integer sums of uint16 raster values (``RASTER_MAX`` = likelihood 1) over the current points.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from bagtools.scan_matching.correlative import CorrelativeReference

#: Raster value of likelihood 1 (the raster is uint16).
RASTER_MAX = 65535
#: The likelihood kernel is cut to 0 beyond this many sigmas.
KERNEL_CUTOFF_SIGMAS = 3.0

#: Memory guard: at most this many rotated points (candidate angles x current points, 8 bytes each).
MAX_ROTATED_POINTS = 16_000_000
#: The coarsest level has blocks of at most 2^this cells square (Cartographer uses 7 levels).
MAX_DEPTH = 7
#: Half-width, in window steps, of the neighbourhood of the best candidate that the covariance is computed from.
COVARIANCE_HALF_WIDTH = 2
# Per-point log-likelihood of a raster value (floored at the kernel cutoff), for the covariance.
_LOG_LIKELIHOOD = np.maximum(np.log(np.maximum(np.arange(RASTER_MAX + 1), 0.5) / RASTER_MAX),
                             -0.5 * KERNEL_CUTOFF_SIGMAS**2).astype(np.float32)
# Up to this many points, a node's score sum fits in uint32.
_UINT32_POINTS = (2**32 - 1) // RASTER_MAX
# Gathers are done in chunks of about this many lookups to bound temporary memory.
_CHUNK_LOOKUPS = 1 << 21


#: match_scans_grid_peaks keeps at most this many nodes per level (the best bounds) while collecting candidates.
MAX_PEAK_NODES = 200_000


def positive(value: float, name: str) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a positive number, got {value!r}") from None
    if not math.isfinite(v) or v <= 0:
        raise ValueError(f"{name} must be a positive finite number, got {value!r}")
    return v


@dataclass(frozen=True)
class Window:
    """The discretized search window and the rotated, binned current points."""

    steps: np.ndarray  # (3,) half-widths in steps: theta (or -1 for a full turn), x, y
    n: tuple[int, int, int]  # candidates along theta, x, y
    angles: np.ndarray  # (A,) candidate headings, rad
    angular_step: float
    base: np.ndarray  # (A, N) flat level-0 index of each point for the window's first x, y candidate
    plane: int  # cells per level
    stride: int  # flat index step of one x step (one y step is 1)
    levels: np.ndarray
    depth: int
    child_steps: np.ndarray  # (3, 1, 4) x, y, flat offsets of the four children of a level-1 node


def build_window(ref: CorrelativeReference, points: np.ndarray, pose0: np.ndarray, search: np.ndarray,
            angular_resolution: float | None) -> Window:
    res = ref.resolution_m
    wx, wy = (np.floor(search[:2] / res + 1e-9)).astype(int).tolist()
    if angular_resolution is None:
        reach = max(math.sqrt(float(np.einsum("ij,ij->i", points, points).max())), res)
        # The farthest point moves by about one cell per step (chord = resolution).
        angular_step = math.acos(max(1.0 - res * res / (2.0 * reach * reach), -1.0))
    else:
        angular_step = positive(angular_resolution, "angular_resolution_rad")
    wa = int(math.floor(search[2] / angular_step + 1e-9))
    full_turn = (2 * wa + 1) * angular_step >= 2 * math.pi  # then every heading once, no duplicates
    na = int(math.ceil(2 * math.pi / angular_step - 1e-9)) if full_turn else 2 * wa + 1
    if float(na) * len(points) > MAX_ROTATED_POINTS:
        raise ValueError(f"the search would rotate {na} x {len(points)} points, above the limit of {MAX_ROTATED_POINTS} "
                         "(MAX_ROTATED_POINTS): use a coarser angular resolution or a smaller rotation search_range")
    if full_turn:
        angular_step = 2 * math.pi / na
        offsets = (np.arange(na) - na // 2) * angular_step
        wa = -1
    else:
        offsets = np.arange(-wa, wa + 1) * angular_step
    nx, ny = 2 * wx + 1, 2 * wy + 1
    # The coarsest level: blocks of 2^depth cells that cover the window in 2 x 2 (or fewer).
    depth = min(max(int(math.ceil(math.log2(max(nx, ny)))) - 1, 0), MAX_DEPTH)
    # Zero padding that makes clipping the binned points exact (see below): 2^depth + 2w below, 2w + 1 above.
    side = 1 << depth
    pyr = ref.pyramid(depth, (side + 2 * wx, side + 2 * wy), (2 * wx + 1, 2 * wy + 1))
    angles = pose0[2] + offsets
    c, s = np.cos(angles), np.sin(angles)
    # Rows 0..A-1: x, rows A..2A-1: y of the rotated points, in cells of the padded raster.
    rot = np.empty((2 * na, 2))
    rot[:na, 0], rot[:na, 1], rot[na:, 0], rot[na:, 1] = c, -s, s, c
    rot *= 1.0 / res
    cells = rot @ points.T
    # A point whose cell is far outside the reference content scores 0 at every candidate and every level;
    # moving it to the nearest such cell keeps that and keeps every lookup inside the padded raster.
    # Clipped (to lo + 0.5 and hi + 0.5, safe from rounding) the cells are positive: truncation is the floor.
    for rows, axis, w in ((cells[:na], 0, wx), (cells[na:], 1, wy)):
        shift = float((pose0[axis] - ref.origin[axis]) / res + pyr.pad_lo[axis])
        np.maximum(rows, pyr.pad_lo[axis] - side - w + 0.5 - shift, out=rows)
        np.minimum(rows, pyr.pad_lo[axis] + ref.raster.shape[axis] + w + 0.5 - shift, out=rows)
        rows += shift
    icells = cells.astype(np.intp)
    stride = pyr.shape[1]
    base = icells[:na] * stride
    base += icells[na:]
    base -= wx * stride + wy  # the window's first candidate: initial pose - (wx, wy) cells
    wrapped = (angles + np.pi) % (2 * np.pi) - np.pi
    return Window(np.array([wa, wx, wy]), (na, nx, ny), wrapped, angular_step, base,
                   pyr.shape[0] * stride, stride, pyr.levels, depth,
                   np.stack((_CHILD_DX, _CHILD_DY, _CHILD_DX * stride + _CHILD_DY))[:, None, :])


def node_scores(win: Window, a: np.ndarray, xy: np.ndarray, level: int) -> np.ndarray:
    """Integer score sums (int64) of nodes at ``level``: angle index ``a``, flat x, y corner ``xy`` (ix * stride + iy)."""
    n_points = win.base.shape[1]
    step = max(1, _CHUNK_LOOKUPS // max(n_points, 1))
    if len(a) <= step:
        idx = win.base.take(a, axis=0)
        idx += (xy + level * win.plane)[:, None]
        # uint32 holds any sum of up to 65537 raster values, and adds up faster than int64
        return win.levels.take(idx).sum(axis=1, dtype=np.uint32 if n_points <= _UINT32_POINTS else np.int64)
    return np.concatenate([node_scores(win, a[i:i + step], xy[i:i + step], level) for i in range(0, len(a), step)])


def _preferred(win: Window, lin: np.ndarray) -> tuple[int, int]:
    """The tie-break key (-distance^2, -lin) of the preferred one of equal-score candidates (linear indices ``lin``).

    Ties go to the candidate fewest steps from the initial pose (squared steps in
    theta, x and y), then to the lowest linear index (theta, x, y order).
    """
    na, nx, ny = win.n
    wa, wx, wy = win.steps.tolist()
    centre_a = wa if wa >= 0 else na // 2
    if lin.size == 1:
        a, rest = divmod(int(lin[0]), nx * ny)
        ix, iy = divmod(rest, ny)
        return -((a - centre_a) ** 2 + (ix - wx) ** 2 + (iy - wy) ** 2), -int(lin[0])
    a, rest = np.divmod(lin, nx * ny)
    ix, iy = np.divmod(rest, ny)
    d2 = (a - centre_a) ** 2 + (ix - wx) ** 2 + (iy - wy) ** 2
    i = np.lexsort((lin, d2))[0]
    return -int(d2[i]), -int(lin[i])


def exhaustive(win: Window, threshold: int) -> tuple[int, int, int]:
    """Best candidate (score sum, linear index a * nx * ny + ix * ny + iy, candidates scored) by scoring all."""
    na, nx, ny = win.n
    offs = (np.arange(nx)[:, None] * win.stride + np.arange(ny)[None, :]).reshape(-1)
    n_points = win.base.shape[1]
    best: tuple[int, int, int] | None = None  # (score, -distance^2, -lin): the larger the better
    if len(offs) * n_points > _CHUNK_LOOKUPS:  # one angle at a time, translations in chunks
        chunks = ((a, node_scores(win, np.full(len(offs), a), offs, 0)) for a in range(na))
    else:  # several angles at a time
        per_angle = max(1, _CHUNK_LOOKUPS // (n_points * len(offs)))
        chunks = ((a0, np.sum(win.levels.take(win.base[a0:a0 + per_angle, None, :] + offs[None, :, None]), axis=2,
                              dtype=np.int64).reshape(-1)) for a0 in range(0, na, per_angle))
    for a0, sums in chunks:
        top = int(sums.max())
        if top < threshold or (best is not None and top < best[0]):
            continue
        cand = (top, *_preferred(win, np.flatnonzero(sums == top) + a0 * len(offs)))
        if best is None or cand > best:
            best = cand
    if best is None:
        return threshold - 1, -1, na * nx * ny
    return best[0], -best[2], na * nx * ny


# Node tables of the branch and bound: rows angle index, x corner, y corner, ix * stride + iy; one column a node.
_NODE_ROWS = 4
# Child corners of a node, in halves of its side: (x, y) = (0, 0), (0, 1), (1, 0), (1, 1).
_CHILD_DX = np.array([0, 0, 1, 1])
_CHILD_DY = np.array([0, 1, 0, 1])


def _roots(win: Window) -> tuple[np.ndarray, np.ndarray]:
    """The coarsest level's nodes (a node table: every angle x the 2^depth blocks covering the window), bounded."""
    na, nx, ny = win.n
    side = 1 << win.depth
    cx, cy = np.arange(0, nx, side), np.arange(0, ny, side)
    nodes = np.empty((_NODE_ROWS, na * len(cx) * len(cy)), dtype=np.int64)
    nodes[0] = np.repeat(np.arange(na), len(cx) * len(cy))
    nodes[1] = np.tile(np.repeat(cx, len(cy)), na)
    nodes[2] = np.tile(cy, na * len(cx))
    nodes[3] = nodes[1] * win.stride + nodes[2]
    return nodes, node_scores(win, nodes[0], nodes[3], win.depth)


def _children(win: Window, parents: np.ndarray, level: int) -> tuple[np.ndarray, np.ndarray]:
    """The level-(``level`` - 1) children of level-``level`` nodes (a node table) and their scores."""
    half = 1 << (level - 1)
    m = parents.shape[1]
    nodes = np.repeat(parents, 4, axis=1)
    nodes.reshape(_NODE_ROWS, m, 4)[1:] += win.child_steps << (level - 1)
    if m and (int(parents[1].max()) + half >= win.n[1] or int(parents[2].max()) + half >= win.n[2]):
        nodes = nodes[:, (nodes[1] < win.n[1]) & (nodes[2] < win.n[2])]
    return nodes, node_scores(win, nodes[0], nodes[3], level - 1)


def _update_best(win: Window, best: tuple[int, int, int] | None, nodes: np.ndarray,
                 scores: np.ndarray) -> tuple[int, int, int] | None:
    """The incumbent (score, -distance^2, -lin) after scoring candidates ``nodes`` (a node table) with ``scores``."""
    if not scores.size:
        return best
    top = int(scores.max())
    if best is not None and top < best[0]:
        return best
    cand = nodes[:, scores == top]
    key = (top, *_preferred(win, (cand[0] * win.n[1] + cand[1]) * win.n[2] + cand[2]))
    return key if best is None or key > best else best


def branch_and_bound(win: Window, threshold: int, beam: int = 8, alpha: float = 0.15,
                      min_batch: int = 64) -> tuple[int, int, int]:
    """Best candidate (score sum, linear index, nodes scored) by branch and bound over the levels.

    A node is an angle and a block of 2^k x 2^k translations (level k), its
    bound the level-k score at the block's corner; the roots are the blocks of
    the coarsest level. First a beam dive (the ``beam`` best nodes of each
    level, down to candidates) gives a good incumbent. Then sweeps from the
    coarsest level to the finest expand, at each level, the open nodes whose
    bound lies in the top ``alpha`` of the gap between the incumbent and the
    level's highest bound (at least ``min_batch`` of them; best first, but in
    vectorized batches), and drop every node bounded below the incumbent, until
    no node is open. A node bounded exactly at the incumbent's score stays: it
    may hold a candidate that wins the tie. The result does not depend on
    ``beam``, ``alpha`` or ``min_batch``, only the work does.
    """
    top = win.depth
    nodes, bound = _roots(win)
    evaluated = bound.size
    incumbent: tuple[int, int, int] | None = None  # (score, -distance^2, -lin) of the best candidate so far
    if top == 0:  # a window of one cell in x and y: the roots are the candidates
        incumbent = _update_best(win, incumbent, nodes, bound)
        nodes, bound = nodes[:, :0], bound[:0]
    # Open nodes of each level: lists of (node table, bounds), concatenated when the level is swept.
    open_nodes: list[list[tuple[np.ndarray, np.ndarray]]] = [[] for _ in range(top + 1)]
    for level in range(top, 0, -1):  # the dive
        if bound.size > beam:
            order = np.argpartition(bound, bound.size - beam)
            rest, pick = order[:-beam], order[-beam:]
            open_nodes[level].append((nodes[:, rest], bound[rest]))
            nodes, bound = nodes[:, pick], bound[pick]
        nodes, bound = _children(win, nodes, level)
        evaluated += bound.size
    incumbent = _update_best(win, incumbent, nodes, bound)
    while any(open_nodes):
        best = threshold if incumbent is None else max(threshold, incumbent[0])
        for level in range(top, 0, -1):
            pending = open_nodes[level]
            if not pending:
                continue
            if len(pending) == 1:
                nodes, bound = pending[0]
            else:
                nodes = np.concatenate([p[0] for p in pending], axis=1)
                bound = np.concatenate([p[1] for p in pending])
            pending.clear()
            keep = bound >= best
            if not keep.all():
                nodes, bound = nodes[:, keep], bound[keep]
            if bound.size > min_batch:
                high = int(bound.max())
                pick = bound >= high - alpha * (high - best)
                if np.count_nonzero(pick) < min_batch:
                    order = np.argpartition(bound, bound.size - min_batch)
                    pick = np.zeros(bound.size, dtype=bool)
                    pick[order[-min_batch:]] = True
                pick_not = ~pick
                pending.append((nodes[:, pick_not], bound[pick_not]))
                nodes = nodes[:, pick]
            if not nodes.shape[1]:
                continue
            children, child_bound = _children(win, nodes, level)
            evaluated += child_bound.size
            if level == 1:
                incumbent = _update_best(win, incumbent, children, child_bound)
                best = max(threshold, incumbent[0])
            else:
                open_nodes[level - 1].append((children, child_bound))
    if incumbent is None or incumbent[0] < threshold:
        return threshold - 1, -1, evaluated
    return incumbent[0], -incumbent[2], evaluated


def olson_covariance(win: Window, a0: int, ix0: int, iy0: int, res: float) -> np.ndarray:
    """Olson's covariance from the likelihood-weighted candidates around the best (see :class:`GridMatchResult`)."""
    na, nx, ny = win.n
    h = COVARIANCE_HALF_WIDTH
    da = np.arange(-h, h + 1)
    if win.steps[0] < 0:  # full turn: neighbours wrap around
        da = da[: min(len(da), na)]
        aa = (a0 + da) % na
    else:
        inside = (a0 + da >= 0) & (a0 + da < na)
        da = da[inside]
        aa = a0 + da
    dx = np.arange(max(-h, -ix0), min(h, nx - 1 - ix0) + 1)
    dy = np.arange(max(-h, -iy0), min(h, ny - 1 - iy0) + 1)
    offsets = ((ix0 + dx)[:, None] * win.stride + (iy0 + dy)[None, :]).reshape(-1)
    idx = win.base.take(aa, axis=0)[:, None, :] + offsets[None, :, None]
    log_l = _LOG_LIKELIHOOD.take(win.levels.take(idx)).sum(axis=2).reshape(-1)  # (angle, x, y) flattened
    w = np.exp(log_l - log_l.max())
    w /= w.sum()
    d = np.empty((3, len(da), len(dx), len(dy)))  # x, y, theta offsets of each candidate from the best
    d[0] = (dx * res)[None, :, None]
    d[1] = (dy * res)[None, None, :]
    d[2] = (da * win.angular_step)[:, None, None]
    d = d.reshape(3, -1)
    centred = d - (d @ w)[:, None]
    cov = (centred * w) @ centred.T
    return cov + np.diag([res * res / 12.0, res * res / 12.0, win.angular_step**2 / 12.0])


def all_above(win: Window, threshold: int) -> tuple[np.ndarray, np.ndarray, int]:
    """Every candidate scoring at least ``threshold`` (score sums, linear indexes), and the nodes scored.

    Level by level from the roots, keeping the nodes whose bound reaches the
    threshold (the best ``MAX_PEAK_NODES`` of them when more do).
    """
    _, nx, ny = win.n
    top = win.depth
    nodes, bound = _roots(win)
    evaluated = bound.size
    for level in range(top, 0, -1):
        keep = bound >= threshold
        nodes, bound = nodes[:, keep], bound[keep]
        if bound.size > MAX_PEAK_NODES:
            pick = np.argpartition(bound, bound.size - MAX_PEAK_NODES)[-MAX_PEAK_NODES:]
            nodes, bound = nodes[:, pick], bound[pick]
        nodes, bound = _children(win, nodes, level)
        evaluated += bound.size
    keep = bound >= threshold
    nodes, bound = nodes[:, keep], bound[keep]
    return bound, (nodes[0] * nx + nodes[1]) * ny + nodes[2], evaluated

