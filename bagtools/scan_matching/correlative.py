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
from bagtools.scan_matching.window_search import (KERNEL_CUTOFF_SIGMAS, MAX_PEAK_NODES, RASTER_MAX, Window, all_above,
                                                  branch_and_bound, build_window, exhaustive, olson_covariance,
                                                  positive)

#: Memory guard: at most this many raster cells over all precomputed levels (2 bytes each).
MAX_RASTER_CELLS = 64_000_000
#: The searches match_scans_grid runs.
METHODS = ("branch_and_bound", "exhaustive")


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
        res = positive(resolution_m, "resolution_m")
        sigma = res if sigma_m is None else positive(sigma_m, "sigma_m")
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


def _failure(pose0: np.ndarray, reason: str, n: int, **extra) -> GridMatchResult:
    return GridMatchResult(pose=pose0.copy(), score=0.0, covariance=np.diag([np.inf, np.inf, np.inf]), ok=False,
                           reason=reason, n_points=n, **extra)


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
    search_fn = branch_and_bound if method == "branch_and_bound" else exhaustive
    best, lin, evaluated = search_fn(prep.win, prep.threshold)
    if best < prep.threshold:
        return prep.no_match(evaluated)
    return prep.result(best, lin, evaluated, f"best of {prep.n_candidates} candidates ({method})")


@dataclass(frozen=True)
class _Prepared:
    """A validated match: the window, the moved-to-raster points, the score threshold."""

    win: Window
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
                               covariance=olson_covariance(win, a, ix, iy, ref.resolution_m), ok=True, reason=reason,
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
        if resolution_m is not None and positive(resolution_m, "resolution_m") != ref.resolution_m:
            raise ValueError(f"resolution_m={resolution_m} differs from the prebuilt reference's {ref.resolution_m}")
    else:
        ref = CorrelativeReference.from_points(reference, 0.05 if resolution_m is None else resolution_m, sigma_m)
    cur = finite_points(current_points, "current points")
    if max_range_m is not None:
        cur = cur[(cur**2).sum(axis=1) <= positive(max_range_m, "max_range_m") ** 2]
    n = len(cur)
    if n < MIN_SCAN_POINTS:
        return _failure(pose0, f"too few valid points in the current scan ({n} < {MIN_SCAN_POINTS})", n)
    if ref.n_points < MIN_SCAN_POINTS:
        return _failure(pose0, f"too few valid points in the reference scan ({ref.n_points} < {MIN_SCAN_POINTS})", n)
    win = build_window(ref, cur, pose0, search, angular_resolution_rad)
    threshold = max(1, int(math.ceil(min_score * n * RASTER_MAX - 1e-9)))
    return _Prepared(win, ref, pose0, n, threshold, min_score)


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
    sep_m, sep_rad = (positive(v, "separation") for v in separation)
    prep = _prepare(current_points, reference, initial_pose, search_range, resolution_m, angular_resolution_rad,
                    max_range_m, sigma_m, min_score, "branch_and_bound")
    if isinstance(prep, GridMatchResult):
        return []
    best, lin, evaluated = branch_and_bound(prep.win, prep.threshold)
    if best < prep.threshold:
        return []
    peaks = [prep.result(best, lin, evaluated, f"best of {prep.n_candidates} candidates (branch_and_bound)")]
    if max_peaks == 1:
        return peaks
    floor = max(prep.threshold, int(math.ceil(min_ratio * best)))
    scores, lins, more = all_above(prep.win, floor)
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
