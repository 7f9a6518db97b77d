"""Correlative scan matching over a search window, the MATLAB ``matchScansGrid`` way.

The reference (one scan or a local map of several scans, in the reference
frame) becomes a likelihood raster: cells of side ``resolution_m`` holding
exp(-d^2 / (2 sigma^2)), d the distance from the cell's centre to the nearest
cell hit by a reference point, and 0 beyond 3 sigma (E. Olson, "Real-time
correlative scan matching", ICRA 2009). The values are stored as integers
(uint16, 65535 = likelihood 1) so every score is an exact integer sum: the
branch and bound and the exhaustive search agree bit for bit, ties included.

A candidate is a pose of the discretized window around ``initial_pose``: x and
y in steps of ``resolution_m`` and theta in steps of the angular resolution.
Its score is the mean raster value at the current points moved by it, each
point looked up in the cell it falls in. For each candidate angle the points
are rotated and binned once; a translation by whole cells only shifts the cell
indices, so all translations of one angle are gathers from the same raster.

The search is the multi-resolution branch and bound of W. Hess et al., "Real-time
loop closure in 2D LIDAR SLAM", ICRA 2016: level k of a precomputed stack of
rasters (each level the maximum of two blocks of the level below, in x then in y) holds at each cell the maximum of
the raster over the 2^k x 2^k cells above and to the right of it, so scoring a
node (an angle and a 2^k x 2^k block of translations) at level k bounds the
score of every candidate in it from above. The roots are the blocks of the
coarsest level (2 x 2 of them cover the window, at most 2^7 cells a side). A
beam dive to the candidates gives a good first incumbent; then the open nodes
are expanded best first, level by level in vectorized batches, and every node
bounded below the incumbent is dropped, until none is open. The result is the
exact best candidate of the window (of equal scores, the one fewest steps from
the initial pose, then the first in theta, x, y order), the same as
:func:`match_scans_grid` with ``method="exhaustive"`` (tests compare them).

The score is the mean raster value over the current points, in [0, 1]; the
covariance follows Olson: the likelihood-weighted spread of the candidates
around the best (see :class:`GridMatchResult`).

Speed (bench/bench_ndt.py, one core, LDS-01 scans of about 300 points): a
window of +-0.3 m, +-0.3 rad at 5 cm (about 7000 candidates) takes about 1 ms
against a prebuilt reference and 2 ms including building it, about 5x less
than scoring every candidate (the search step alone, without binning the points
and the covariance, 7-10x); a window of +-4 m and every heading (about 11
million candidates) against a local map of 5 scans takes about 20-25 ms, some
500x less than the exhaustive search's 9-12 s. Followed by NDT (widened cells
of 0.5 m), the +-0.3 m window from a zero initial pose recovers every pair of
the bench within 2 cm and 0.5 degrees.

Pose convention, as :func:`bagtools.scan_matching.match_scans`: the pose [x, y, theta]
(m, m, rad) is the pose of the current scan's frame in the reference frame,
``p_ref = R(theta) p_cur + [x, y]``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from bagtools.scan_matching.grid import finite_points
from bagtools.scan_matching.matcher import MIN_SCAN_POINTS, ranges_to_points

#: Raster value of likelihood 1 (the raster is uint16).
RASTER_MAX = 65535
#: The likelihood kernel is cut to 0 beyond this many sigmas.
KERNEL_CUTOFF_SIGMAS = 3.0
#: Memory guard: at most this many raster cells over all precomputed levels (2 bytes each).
MAX_RASTER_CELLS = 64_000_000
#: Memory guard: at most this many rotated points (candidate angles x current points, 8 bytes each).
MAX_ROTATED_POINTS = 16_000_000
#: The coarsest level has blocks of at most 2^this cells square (Cartographer uses 7 levels).
MAX_DEPTH = 7
#: Half-width, in window steps, of the neighbourhood of the best candidate that the covariance is computed from.
COVARIANCE_HALF_WIDTH = 2
METHODS = ("branch_and_bound", "exhaustive")
# Per-point log-likelihood of a raster value (floored at the kernel cutoff), for the covariance.
_LOG_LIKELIHOOD = np.maximum(np.log(np.maximum(np.arange(RASTER_MAX + 1), 0.5) / RASTER_MAX),
                             -0.5 * KERNEL_CUTOFF_SIGMAS**2).astype(np.float32)
# Up to this many points, a node's score sum fits in uint32.
_UINT32_POINTS = (2**32 - 1) // RASTER_MAX
# Gathers are done in chunks of about this many lookups to bound temporary memory.
_CHUNK_LOOKUPS = 1 << 21


@dataclass
class _Pyramid:
    """Max-pooled levels 0..depth of a reference raster padded with zeros, flattened."""

    depth: int
    pad_lo: tuple[int, int]  # zero cells added below the raster along x and y
    pad_hi: tuple[int, int]  # zero cells added above
    shape: tuple[int, int]
    levels: np.ndarray  # ((depth + 1) * shape[0] * shape[1],) uint16; level k at k * P + ix * shape[1] + iy


def _kernel_stamps(res: float, sigma: float, cutoff: float, ny: int) -> list[tuple[int, int]]:
    """(flat raster offset, uint16 likelihood) of the cells within ``cutoff`` (m) of a cell, ascending by value.

    The likelihood of a cell ``d`` metres from the nearest point is exp(-d^2 / 2 sigma^2), d measured between
    cell centres as scipy's ``distance_transform_edt(sampling=res)`` does, scaled to ``RASTER_MAX`` and rounded.
    """
    r = int(math.floor(cutoff / res + 1e-9)) + 1
    dx, dy = np.meshgrid(np.arange(-r, r + 1, dtype=np.float64), np.arange(-r, r + 1, dtype=np.float64),
                         indexing="ij")
    dist = np.sqrt((dx * res) ** 2 + (dy * res) ** 2)
    keep = dist <= cutoff
    values = np.rint(np.exp(-0.5 * (dist[keep] / sigma) ** 2) * RASTER_MAX).astype(np.uint16)
    offsets = dx[keep].astype(np.intp) * ny + dy[keep].astype(np.intp)
    order = np.argsort(values, kind="stable")
    return [(int(offsets[k]), int(values[k])) for k in order]


@dataclass(frozen=True, eq=False)
class CorrelativeReference:
    """The likelihood raster of a reference scan or local map; build with :meth:`from_points`.

    Build it once to match many scans against the same reference (loop closure
    against a submap): the max-pooled levels of the branch and bound are also
    kept and reused while later searches need no larger ones.

    Attributes:
        resolution_m: side of a raster cell, metres (also the translation step of the search).
        sigma_m: standard deviation of the likelihood kernel, metres.
        n_points: finite reference points used.
        origin: (2,) reference-frame x, y (m) of the lower-left corner of raster cell (0, 0).
        raster: (nx, ny) uint16 likelihood * 65535 (``RASTER_MAX``), indexed [ix, iy];
            cell (ix, iy) spans origin + [ix, ix + 1) * resolution in x, likewise in y.
    """

    resolution_m: float
    sigma_m: float
    n_points: int
    origin: np.ndarray
    raster: np.ndarray
    _pyramid: list = field(default_factory=list, repr=False)

    @classmethod
    def from_points(cls, points_m: np.ndarray, resolution_m: float = 0.05,
                    sigma_m: float | None = None) -> CorrelativeReference:
        """The likelihood raster of (N, 2) reference points (m, reference frame; non-finite rows dropped).

        ``sigma_m`` (default: ``resolution_m``) is the spread of the likelihood
        around each point, metres. Several scans (a local map) are passed as
        their points moved into the reference frame and stacked.

        Raises:
            ValueError: on a bad shape or parameter, or a raster above ``MAX_RASTER_CELLS``.
        """
        res = _positive(resolution_m, "resolution_m")
        sigma = res if sigma_m is None else _positive(sigma_m, "sigma_m")
        pts = finite_points(points_m, "reference points")
        if len(pts) == 0:
            return cls(res, sigma, 0, np.zeros(2), np.zeros((1, 1), np.uint16))
        cutoff = KERNEL_CUTOFF_SIGMAS * sigma
        margin = int(math.ceil(cutoff / res)) + 1
        cells = np.floor(pts / res)
        lo = cells.min(axis=0) - margin
        shape = cells.max(axis=0) - lo + margin + 1
        if float(shape[0]) * float(shape[1]) > MAX_RASTER_CELLS:
            raise ValueError(f"the reference raster would need {shape[0]:.0f} x {shape[1]:.0f} cells, above the limit of "
                             f"{MAX_RASTER_CELLS} (MAX_RASTER_CELLS): use a coarser resolution_m or a smaller reference")
        idx = (cells - lo).astype(np.intp)
        nx, ny = shape.astype(np.intp).tolist()
        occupied = np.unique(idx[:, 0] * ny + idx[:, 1])
        # Each occupied cell stamps the kernel around it (the margin keeps every stamp inside); a cell keeps the
        # largest value, that of its nearest occupied cell: the raster of a Euclidean distance transform cut off
        # at ``cutoff``, computed only where it is not zero (a few dozen offsets instead of every cell).
        raster = np.zeros(nx * ny, dtype=np.uint16)
        for flat_offset, value in _kernel_stamps(res, sigma, cutoff, ny):
            raster[occupied + flat_offset] = value  # ascending values: the largest is written last
        return cls(res, sigma, len(pts), lo * res, raster.reshape(nx, ny))

    def score(self, points_m: np.ndarray, pose: np.ndarray) -> float:
        """The score :func:`match_scans_grid` gives ``points_m`` ((N, 2), their own frame, m) at ``pose``
        [x, y, theta] in this reference's frame, without a search: the mean raster likelihood in [0, 1]
        (points off the raster count 0; 0.0 for no finite point)."""
        pts = finite_points(points_m, "points")
        if len(pts) == 0:
            return 0.0
        x, y, theta = (float(v) for v in pose)
        c, s = math.cos(theta), math.sin(theta)
        moved = pts @ np.array([[c, s], [-s, c]]) + np.array([x, y])
        cells = np.floor((moved - self.origin) / self.resolution_m).astype(np.intp)
        nx, ny = self.raster.shape
        inside = (cells[:, 0] >= 0) & (cells[:, 0] < nx) & (cells[:, 1] >= 0) & (cells[:, 1] < ny)
        total = int(self.raster[cells[inside, 0], cells[inside, 1]].sum(dtype=np.int64))
        return total / (len(pts) * RASTER_MAX)

    def pyramid(self, depth: int, pad_lo: tuple[int, int], pad_hi: tuple[int, int]) -> _Pyramid:
        """Levels 0..``depth`` with at least ``pad_lo``/``pad_hi`` zero cells (x, y) around the raster (cached)."""
        if self._pyramid:
            cached = self._pyramid[0]
            if (cached.depth >= depth and cached.pad_lo[0] >= pad_lo[0] and cached.pad_lo[1] >= pad_lo[1]
                    and cached.pad_hi[0] >= pad_hi[0] and cached.pad_hi[1] >= pad_hi[1]):
                return cached
            # Grow to cover both the cached and the new request, so alternating windows do not rebuild.
            depth = max(depth, cached.depth)
            pad_lo = (max(pad_lo[0], cached.pad_lo[0]), max(pad_lo[1], cached.pad_lo[1]))
            pad_hi = (max(pad_hi[0], cached.pad_hi[0]), max(pad_hi[1], cached.pad_hi[1]))
        rx, ry = self.raster.shape
        nx, ny = rx + pad_lo[0] + pad_hi[0], ry + pad_lo[1] + pad_hi[1]
        total = float(depth + 1) * float(nx) * float(ny)
        if total > MAX_RASTER_CELLS:
            raise ValueError(f"the search would need {depth + 1} rasters of {nx} x {ny} cells ({total:.3g}), "
                             f"above the limit of {MAX_RASTER_CELLS} (MAX_RASTER_CELLS): use a coarser resolution_m "
                             "or a smaller search_range")
        levels = np.zeros((depth + 1, nx, ny), dtype=np.uint16)
        levels[0, pad_lo[0]:pad_lo[0] + rx, pad_lo[1]:pad_lo[1] + ry] = self.raster
        for k in range(1, depth + 1):
            # Window [i, i + 2^k) in both axes (the maximum over the block above and to the right; cells past the
            # edge count 0): the two blocks of 2^(k-1) of the level below, in x, then in y.
            half, below, level = 1 << (k - 1), levels[k - 1], levels[k]
            level[:] = below
            np.maximum(below[:-half], below[half:], out=level[:-half])
            in_x = level.copy()
            np.maximum(in_x[:, :-half], in_x[:, half:], out=level[:, :-half])
        built = _Pyramid(depth, (int(pad_lo[0]), int(pad_lo[1])), (int(pad_hi[0]), int(pad_hi[1])), (nx, ny),
                         levels.reshape(-1))
        self._pyramid[:] = [built]
        return built


@dataclass(frozen=True)
class GridMatchResult:
    """The outcome of one correlative scan match; MATLAB ``matchScansGrid`` returns pose, score and covariance.

    Attributes:
        pose: [x, y, theta] (m, m, rad) of the current scan's frame in the
            reference frame (``p_ref = R(theta) p_cur + [x, y]``): the best
            candidate of the discretized window (theta wrapped to [-pi, pi)).
        score: mean over the current points of the likelihood raster at the
            moved points, in [0, 1] (1: every point on a reference point's cell).
        covariance: 3x3 covariance of [x, y, theta] (m^2, m^2, rad^2; m rad off
            the diagonal), Olson's: the spread of the candidates within
            ``COVARIANCE_HALF_WIDTH`` steps of the best, each weighted by its
            likelihood (the product over points of the raster values, floored at
            the kernel cutoff), plus the discretization's own variance
            (step^2 / 12 in each coordinate). Infinite diagonal on failure.
        ok: True when a pose was found; False with ``reason`` on failure.
        reason: what was done, or why the match failed, in words.
        n_points: finite current points used.
        index: (theta, x, y) steps of ``pose`` from ``initial_pose`` (for a
            full-turn window, theta steps from the initial heading modulo the turn);
            None on failure.
        n_candidates: candidate poses in the discretized window.
        n_evaluated: nodes scored (all levels, the covariance neighbourhood excluded);
            ``n_candidates`` for the exhaustive search.
        resolution_m: translation step, metres.
        angular_resolution_rad: rotation step, radians.
    """

    pose: np.ndarray
    score: float
    covariance: np.ndarray
    ok: bool
    reason: str
    n_points: int = 0
    index: tuple[int, int, int] | None = None
    n_candidates: int = 0
    n_evaluated: int = 0
    resolution_m: float = 0.0
    angular_resolution_rad: float = 0.0

    @property
    def converged(self) -> bool:
        """Alias of ``ok``, as :class:`bagtools.scan_matching.NdtResult` names it."""
        return self.ok


def _positive(value: float, name: str) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a positive number, got {value!r}") from None
    if not math.isfinite(v) or v <= 0:
        raise ValueError(f"{name} must be a positive finite number, got {value!r}")
    return v


def _failure(pose0: np.ndarray, reason: str, n: int, **extra) -> GridMatchResult:
    return GridMatchResult(pose=pose0.copy(), score=0.0, covariance=np.diag([np.inf, np.inf, np.inf]), ok=False,
                           reason=reason, n_points=n, **extra)


@dataclass(frozen=True)
class _Window:
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


def _window(ref: CorrelativeReference, points: np.ndarray, pose0: np.ndarray, search: np.ndarray,
            angular_resolution: float | None) -> _Window:
    res = ref.resolution_m
    wx, wy = (np.floor(search[:2] / res + 1e-9)).astype(int).tolist()
    if angular_resolution is None:
        reach = max(math.sqrt(float(np.einsum("ij,ij->i", points, points).max())), res)
        # The farthest point moves by about one cell per step (chord = resolution).
        angular_step = math.acos(max(1.0 - res * res / (2.0 * reach * reach), -1.0))
    else:
        angular_step = _positive(angular_resolution, "angular_resolution_rad")
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
    return _Window(np.array([wa, wx, wy]), (na, nx, ny), wrapped, angular_step, base,
                   pyr.shape[0] * stride, stride, pyr.levels, depth,
                   np.stack((_CHILD_DX, _CHILD_DY, _CHILD_DX * stride + _CHILD_DY))[:, None, :])


def _scores(win: _Window, a: np.ndarray, xy: np.ndarray, level: int) -> np.ndarray:
    """Integer score sums (int64) of nodes at ``level``: angle index ``a``, flat x, y corner ``xy`` (ix * stride + iy)."""
    n_points = win.base.shape[1]
    step = max(1, _CHUNK_LOOKUPS // max(n_points, 1))
    if len(a) <= step:
        idx = win.base.take(a, axis=0)
        idx += (xy + level * win.plane)[:, None]
        # uint32 holds any sum of up to 65537 raster values, and adds up faster than int64
        return win.levels.take(idx).sum(axis=1, dtype=np.uint32 if n_points <= _UINT32_POINTS else np.int64)
    return np.concatenate([_scores(win, a[i:i + step], xy[i:i + step], level) for i in range(0, len(a), step)])


def _preferred(win: _Window, lin: np.ndarray) -> tuple[int, int]:
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


def _exhaustive(win: _Window, threshold: int) -> tuple[int, int, int]:
    """Best candidate (score sum, linear index a * nx * ny + ix * ny + iy, candidates scored) by scoring all."""
    na, nx, ny = win.n
    offs = (np.arange(nx)[:, None] * win.stride + np.arange(ny)[None, :]).reshape(-1)
    n_points = win.base.shape[1]
    best: tuple[int, int, int] | None = None  # (score, -distance^2, -lin): the larger the better
    if len(offs) * n_points > _CHUNK_LOOKUPS:  # one angle at a time, translations in chunks
        chunks = ((a, _scores(win, np.full(len(offs), a), offs, 0)) for a in range(na))
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


def _roots(win: _Window) -> tuple[np.ndarray, np.ndarray]:
    """The coarsest level's nodes (a node table: every angle x the 2^depth blocks covering the window), bounded."""
    na, nx, ny = win.n
    side = 1 << win.depth
    cx, cy = np.arange(0, nx, side), np.arange(0, ny, side)
    nodes = np.empty((_NODE_ROWS, na * len(cx) * len(cy)), dtype=np.int64)
    nodes[0] = np.repeat(np.arange(na), len(cx) * len(cy))
    nodes[1] = np.tile(np.repeat(cx, len(cy)), na)
    nodes[2] = np.tile(cy, na * len(cx))
    nodes[3] = nodes[1] * win.stride + nodes[2]
    return nodes, _scores(win, nodes[0], nodes[3], win.depth)


def _children(win: _Window, parents: np.ndarray, level: int) -> tuple[np.ndarray, np.ndarray]:
    """The level-(``level`` - 1) children of level-``level`` nodes (a node table) and their scores."""
    half = 1 << (level - 1)
    m = parents.shape[1]
    nodes = np.repeat(parents, 4, axis=1)
    nodes.reshape(_NODE_ROWS, m, 4)[1:] += win.child_steps << (level - 1)
    if m and (int(parents[1].max()) + half >= win.n[1] or int(parents[2].max()) + half >= win.n[2]):
        nodes = nodes[:, (nodes[1] < win.n[1]) & (nodes[2] < win.n[2])]
    return nodes, _scores(win, nodes[0], nodes[3], level - 1)


def _update_best(win: _Window, best: tuple[int, int, int] | None, nodes: np.ndarray,
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


def _branch_and_bound(win: _Window, threshold: int, beam: int = 8, alpha: float = 0.15,
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


def _covariance(win: _Window, a0: int, ix0: int, iy0: int, res: float) -> np.ndarray:
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


def match_scans_grid(
    current_points: np.ndarray,
    reference: np.ndarray | CorrelativeReference,
    *,
    initial_pose: tuple[float, float, float] | np.ndarray = (0.0, 0.0, 0.0),
    search_range: tuple[float, float, float] | np.ndarray = (4.0, 4.0, math.pi / 4),
    resolution_m: float | None = None,
    angular_resolution_rad: float | None = None,
    max_range_m: float | None = None,
    sigma_m: float | None = None,
    min_score: float = 0.0,
    method: str = "branch_and_bound",
) -> GridMatchResult:
    """Best pose of the ``current`` scan in the ``reference`` frame over a search window (MATLAB ``matchScansGrid``).

    Args:
        current_points: (N, 2) current scan x, y in its own frame, metres; non-finite rows are dropped.
        reference: (M, 2) reference points in the reference frame, metres (one
            scan, or several scans moved into that frame), or a
            :class:`CorrelativeReference` built from them (reuse it to match many scans).
        initial_pose: centre of the window, [x, y, theta] (m, m, rad), same
            convention as the result: ``p_ref = R(theta) p_cur + [x, y]``.
        search_range: half-widths of the window (x_m, y_m, theta_rad): poses
            initial_pose +- search_range (MATLAB's defaults 4 m, 4 m, pi/4); a
            theta range whose window spans a full turn searches every heading once.
        resolution_m: translation step and raster cell, metres (default 0.05,
            MATLAB's; must equal a prebuilt reference's own, which it defaults to).
        angular_resolution_rad: rotation step, radians; default: the angle that
            moves the farthest current point by one cell.
        max_range_m: current points farther than this from the sensor are dropped (default: keep all).
        sigma_m: likelihood kernel spread (default: the resolution); ignored for a prebuilt reference.
        min_score: the match fails unless the best score (in [0, 1]) reaches it;
            a higher value also prunes more. With 0, some point must land near the reference.
        method: "branch_and_bound" or "exhaustive" (every candidate scored, the
            same result, much slower; the reference for tests and benchmarks).

    Returns:
        A :class:`GridMatchResult`. Fewer than 5 finite points in either scan, or
        no candidate reaching ``min_score``, gives ``ok=False`` with the reason,
        the initial pose and an infinite covariance, never an exception.

    Raises:
        ValueError: on bad shapes or parameters, or a window and resolution that
            would need more than ``MAX_RASTER_CELLS`` raster cells or
            ``MAX_ROTATED_POINTS`` rotated points (checked before allocating).
    """
    prep = _prepare(current_points, reference, initial_pose, search_range, resolution_m, angular_resolution_rad,
                    max_range_m, sigma_m, min_score, method)
    if isinstance(prep, GridMatchResult):
        return prep
    search_fn = _branch_and_bound if method == "branch_and_bound" else _exhaustive
    best, lin, evaluated = search_fn(prep.win, prep.threshold)
    if best < prep.threshold:
        return prep.no_match(evaluated)
    return prep.result(best, lin, evaluated, f"best of {prep.n_candidates} candidates ({method})")


@dataclass(frozen=True)
class _Prepared:
    """A validated match: the window, the moved-to-raster points, the score threshold."""

    win: _Window
    ref: CorrelativeReference
    pose0: np.ndarray
    n: int
    threshold: int
    min_score: float

    @property
    def n_candidates(self) -> int:
        na, nx, ny = self.win.n
        return na * nx * ny

    def stats(self) -> dict:
        return dict(n_candidates=self.n_candidates, resolution_m=self.ref.resolution_m,
                    angular_resolution_rad=self.win.angular_step)

    def no_match(self, evaluated: int) -> GridMatchResult:
        why = ("no current point lands near the reference anywhere in the search window" if self.threshold == 1
               else f"no pose in the search window reaches min_score={self.min_score}")
        return _failure(self.pose0, why, self.n, n_evaluated=evaluated, **self.stats())

    def result(self, score_sum: int, lin: int, evaluated: int, reason: str) -> GridMatchResult:
        """The candidate of linear index ``lin`` (a * nx * ny + ix * ny + iy) and score sum ``score_sum``."""
        win, ref, pose0 = self.win, self.ref, self.pose0
        na, nx, ny = win.n
        a, rest = divmod(int(lin), nx * ny)
        ix, iy = divmod(rest, ny)
        wa, wx, wy = win.steps.tolist()
        da = a - wa if wa >= 0 else a - na // 2
        pose = np.array([pose0[0] + (ix - wx) * ref.resolution_m, pose0[1] + (iy - wy) * ref.resolution_m,
                         win.angles[a]])
        return GridMatchResult(pose=pose, score=int(score_sum) / (self.n * RASTER_MAX),
                               covariance=_covariance(win, a, ix, iy, ref.resolution_m), ok=True, reason=reason,
                               n_points=self.n, index=(da, ix - wx, iy - wy), n_evaluated=evaluated, **self.stats())


def _prepare(current_points, reference, initial_pose, search_range, resolution_m, angular_resolution_rad,
             max_range_m, sigma_m, min_score, method) -> _Prepared | GridMatchResult:
    """Validate the arguments of :func:`match_scans_grid` and build its window (or the failure result)."""
    pose0 = np.asarray(initial_pose, dtype=np.float64).reshape(-1)
    if pose0.shape != (3,) or not np.isfinite(pose0).all():
        raise ValueError(f"initial_pose must be three finite numbers [x, y, theta], got {initial_pose!r}")
    search = np.asarray(search_range, dtype=np.float64).reshape(-1)
    if search.shape != (3,) or not np.isfinite(search).all() or (search < 0).any():
        raise ValueError(f"search_range must be three non-negative numbers (x_m, y_m, theta_rad), got {search_range!r}")
    if method not in METHODS:
        raise ValueError(f"method must be one of {', '.join(METHODS)}, got {method!r}")
    if not (math.isfinite(min_score) and 0.0 <= min_score <= 1.0):
        raise ValueError(f"min_score must be in [0, 1], got {min_score!r}")
    if isinstance(reference, CorrelativeReference):
        ref = reference
        if resolution_m is not None and _positive(resolution_m, "resolution_m") != ref.resolution_m:
            raise ValueError(f"resolution_m={resolution_m} differs from the prebuilt reference's {ref.resolution_m}")
    else:
        ref = CorrelativeReference.from_points(reference, 0.05 if resolution_m is None else resolution_m, sigma_m)
    cur = finite_points(current_points, "current points")
    if max_range_m is not None:
        cur = cur[(cur**2).sum(axis=1) <= _positive(max_range_m, "max_range_m") ** 2]
    n = len(cur)
    if n < MIN_SCAN_POINTS:
        return _failure(pose0, f"too few valid points in the current scan ({n} < {MIN_SCAN_POINTS})", n)
    if ref.n_points < MIN_SCAN_POINTS:
        return _failure(pose0, f"too few valid points in the reference scan ({ref.n_points} < {MIN_SCAN_POINTS})", n)
    win = _window(ref, cur, pose0, search, angular_resolution_rad)
    threshold = max(1, int(math.ceil(min_score * n * RASTER_MAX - 1e-9)))
    return _Prepared(win, ref, pose0, n, threshold, min_score)


#: match_scans_grid_peaks keeps at most this many nodes per level (the best bounds) while collecting candidates.
MAX_PEAK_NODES = 200_000


def match_scans_grid_peaks(
    current_points: np.ndarray,
    reference: np.ndarray | CorrelativeReference,
    *,
    initial_pose: tuple[float, float, float] | np.ndarray = (0.0, 0.0, 0.0),
    search_range: tuple[float, float, float] | np.ndarray = (4.0, 4.0, math.pi / 4),
    max_peaks: int = 5,
    min_ratio: float = 0.6,
    separation: tuple[float, float] = (0.5, 0.3),
    resolution_m: float | None = None,
    angular_resolution_rad: float | None = None,
    max_range_m: float | None = None,
    sigma_m: float | None = None,
    min_score: float = 0.0,
) -> list[GridMatchResult]:
    """The distinct good poses of a search window, best first: for scenes that repeat (corridors, symmetric rooms).

    The first is :func:`match_scans_grid`'s exact best; the others are the
    best candidates of other places in the window scoring at least
    ``min_ratio`` of it: each at least ``separation`` (metres, radians) from
    every peak before it in translation or in rotation. At most ``max_peaks``.
    A caller with other evidence (a motion prior, a larger map) picks among
    them. The other peaks are collected by a branch and bound at the fixed
    threshold ``min_ratio`` x best (every candidate above it, or, when more
    than ``MAX_PEAK_NODES`` nodes of a level pass, those under the best
    bounds). Arguments and result as :func:`match_scans_grid`; an empty list
    when the window holds no match.
    """
    if not (isinstance(max_peaks, int) and max_peaks >= 1):
        raise ValueError(f"max_peaks must be a positive integer, got {max_peaks!r}")
    if not (math.isfinite(min_ratio) and 0.0 < min_ratio <= 1.0):
        raise ValueError(f"min_ratio must be in (0, 1], got {min_ratio!r}")
    sep_m, sep_rad = (_positive(v, "separation") for v in separation)
    prep = _prepare(current_points, reference, initial_pose, search_range, resolution_m, angular_resolution_rad,
                    max_range_m, sigma_m, min_score, "branch_and_bound")
    if isinstance(prep, GridMatchResult):
        return []
    best, lin, evaluated = _branch_and_bound(prep.win, prep.threshold)
    if best < prep.threshold:
        return []
    peaks = [prep.result(best, lin, evaluated, f"best of {prep.n_candidates} candidates (branch_and_bound)")]
    if max_peaks == 1:
        return peaks
    floor = max(prep.threshold, int(math.ceil(min_ratio * best)))
    scores, lins, more = _all_above(prep.win, floor)
    win = prep.win
    na, nx, ny = win.n
    a, rest = np.divmod(lins, nx * ny)
    ix, iy = np.divmod(rest, ny)
    xy = np.stack((ix, iy), axis=1) * prep.ref.resolution_m
    theta = win.angles[a]
    order = np.argsort(-scores, kind="stable")
    xy, theta, scores, lins = xy[order], theta[order], scores[order], lins[order]
    taken_xy = [np.array([(peaks[0].index[1] + win.steps[1]) * prep.ref.resolution_m,
                          (peaks[0].index[2] + win.steps[2]) * prep.ref.resolution_m])]
    taken_theta = [float(peaks[0].pose[2])]
    free = np.ones(len(scores), dtype=bool)
    while len(peaks) < max_peaks:
        for t_xy, t_theta in zip(taken_xy[-1:], taken_theta[-1:]):
            near = np.hypot(*(xy - t_xy).T) < sep_m
            near &= np.abs((theta - t_theta + np.pi) % (2 * np.pi) - np.pi) < sep_rad
            free &= ~near
        left = np.flatnonzero(free)
        if not left.size:
            break
        i = int(left[0])
        peaks.append(prep.result(int(scores[i]), int(lins[i]), evaluated + more,
                                 f"peak {len(peaks) + 1} of {prep.n_candidates} candidates (branch_and_bound)"))
        taken_xy.append(xy[i])
        taken_theta.append(float(theta[i]))
    return peaks


def _all_above(win: _Window, threshold: int) -> tuple[np.ndarray, np.ndarray, int]:
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


def match_scans_grid_ranges(
    current_ranges: np.ndarray,
    current_angles: np.ndarray,
    reference_ranges: np.ndarray,
    reference_angles: np.ndarray,
    *,
    initial_pose: tuple[float, float, float] | np.ndarray = (0.0, 0.0, 0.0),
    search_range: tuple[float, float, float] | np.ndarray = (4.0, 4.0, math.pi / 4),
    resolution_m: float | None = None,
    angular_resolution_rad: float | None = None,
    range_limits: tuple[float, float] | None = None,
    sigma_m: float | None = None,
    min_score: float = 0.0,
    method: str = "branch_and_bound",
) -> GridMatchResult:
    """:func:`match_scans_grid` on two scans given as ranges (m) and beam angles (rad).

    Beams with a non-finite or non-positive range (or outside ``range_limits``,
    metres, when given) are dropped, as LaserScan consumers do.
    """
    return match_scans_grid(
        ranges_to_points(current_ranges, current_angles, range_limits),
        ranges_to_points(reference_ranges, reference_angles, range_limits),
        initial_pose=initial_pose, search_range=search_range, resolution_m=resolution_m,
        angular_resolution_rad=angular_resolution_rad, sigma_m=sigma_m, min_score=min_score, method=method,
    )


def voxel_subsample(points: np.ndarray, voxel_m: float) -> np.ndarray:
    """The first point of each occupied ``voxel_m`` square cell of (N,2) ``points`` (metres)."""
    if len(points) == 0:
        return points
    cells = np.floor(points / voxel_m).astype(np.int64)
    cells -= cells.min(axis=0)
    keys = cells[:, 0] * (int(cells[:, 1].max()) + 1) + cells[:, 1]
    _, first = np.unique(keys, return_index=True)
    return points[np.sort(first)]
