"""The reference side of 2D NDT: four overlapping grids of normal distributions.

Following Biber and Strasser (IROS 2003), the reference scan's plane is covered
by four grids of square cells of side ``cell_size``, the second to fourth shifted
by half a cell in x, in y and in both. Each cell holding at least three reference
points gets the mean and covariance of those points; the covariance is kept from
going singular by raising its smallest eigenvalue to 0.001 of the largest.

``cell_model="paper"`` (the default, as Biber and Strasser and MATLAB's
matchScans) uses those covariances as they are. ``cell_model="widened"`` makes
two changes that remove a bias of the paper's model (measured on a simulated
lap, consecutive scans 5 cm apart: about 1.9 mm sideways per pair with 1 m
cells, 1.1 mm with 0.5 m cells, always to the same side):

* The spread along a cell's major axis (its variance minus the minor one) is
  multiplied by ``MAJOR_AXIS_INFLATION`` (a round cell stays round). Where along a wall or a pillar's arc the points of a
  scan lie depends on the sensor's position (beams are denser near the sensor
  and visibility changes), not on the pose being estimated; with the paper's
  covariance the score pulls the current points' density towards the reference
  points' density, which for curved or cornered structure shifts the optimum.
  Widening the major axis leaves mostly the across-structure distance
  (point-to-line like), as ICP variants do.
* The whole covariance is multiplied by ``RESIDUAL_COVARIANCE_FACTOR`` = 2: a
  current point's offset from the cell mean is the difference of two scans'
  noisy samples, so its spread is about twice one scan's.

Together they cut that bias to about 0.3 mm per pair with 0.5 m cells and the
median error of bench/bench_ndt.py (0.5 m cells) from 2.2 mm to about 1.9 mm.

All four grids are stored as one dense table over the reference scan's bounding
box (plus a ring of empty border cells), so looking up the cell of many points
in all four grids is a few vectorized integer operations and one gather.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from bagtools.limits import check_memory

#: A cell needs this many reference points to get a normal distribution.
MIN_POINTS_PER_CELL = 3
#: The smallest covariance eigenvalue is raised to this fraction of the largest.
MIN_EIGENVALUE_RATIO = 1e-3
#: Cell models: the paper's covariances, or widened along the major axis (see the module docstring).
CELL_MODELS = ("paper", "widened")
#: With cell_model="widened": the major minus the minor (regularized) variance of a cell is multiplied by this.
MAJOR_AXIS_INFLATION = 100.0
#: The covariance is then multiplied by this (the residual of two noisy scans).
RESIDUAL_COVARIANCE_FACTOR = 2.0

# Columns of NdtReference.table.
_MX, _MY, _IA, _IB, _IC, _W = range(6)

_BYTES_PER_CELL = 14 * 8  # the table's six rows and the bincounts, float64, per cell of each grid


def finite_points(points: np.ndarray, what: str) -> np.ndarray:
    """Validate an (N, 2) array of x, y points (metres) and keep its finite rows, as float64."""
    arr = np.asarray(points, dtype=np.float64)
    if arr.ndim != 2 or arr.shape[1] != 2:
        raise ValueError(f"{what} must be an (N, 2) array of x, y points, got shape {arr.shape}")
    return arr[np.isfinite(arr).all(axis=1)]


@dataclass(frozen=True)
class NdtReference:
    """The four shifted NDT grids of one reference scan; build with :meth:`from_points`.

    Build it once and pass it to :func:`bagtools.scan_matching.match_scans` for every scan
    matched against the same reference (e.g. scan k is the reference of scan k+1
    and the current scan of the match against scan k-1).

    Attributes:
        cell_size: side of a cell, metres.
        n_points: finite reference points used.
        n_cells: cells (over the four grids) that hold a normal distribution.
        origins: (4, 2) lower-left corner of each grid in the reference frame, metres.
        shape: cells per grid along x and y (the same for all four grids).
        table: (6, 4 * nx * ny) per cell (grid g, column i, row j at
            g * nx * ny + i * ny + j): mean x, mean y (m), the inverse covariance
            entries a, b, c of [[a, b], [b, c]] (1/m^2), and 1.0 if the cell holds
            a distribution else 0.0 (then the other entries are 0).
        clip_hi, grid_bases: lookup helpers (highest grid-0 coordinate kept, first
            table column of each grid).
    """

    cell_size: float
    n_points: int
    n_cells: int
    origins: np.ndarray
    shape: tuple[int, int]
    table: np.ndarray
    clip_hi: np.ndarray = field(repr=False)
    grid_bases: np.ndarray = field(repr=False)

    @classmethod
    def from_points(cls, points: np.ndarray, cell_size: float = 1.0, cell_model: str = "paper") -> NdtReference:
        """Build the four grids from an (N, 2) reference scan in its own frame (metres).

        ``cell_model``: "paper" (Biber and Strasser's covariances) or "widened"
        (see the module docstring).

        Non-finite rows are dropped. An empty or too sparse scan gives a reference
        with ``n_cells == 0``, which matching reports as a failure.
        """
        if not np.isfinite(cell_size) or cell_size <= 0:
            raise ValueError(f"cell_size must be a positive number of metres, got {cell_size}")
        if cell_model not in CELL_MODELS:
            raise ValueError(f"cell_model must be one of {', '.join(CELL_MODELS)}, got {cell_model!r}")
        pts = finite_points(points, "reference points")
        cell = float(cell_size)
        half = cell / 2.0
        shifts = np.array([[0.0, 0.0], [half, 0.0], [0.0, half], [half, half]])
        if len(pts) == 0:
            lo = hi = np.zeros(2)
        else:
            lo, hi = pts.min(axis=0), pts.max(axis=0)
        # Empty border cells (one ring below, two above): out-of-box lookups are clipped onto them.
        origins = lo[None, :] - shifts - cell
        extent = np.floor((hi - lo + half) / cell) + 4
        check_memory(4 * float(extent[0]) * float(extent[1]) * _BYTES_PER_CELL,
                     f"NDT grids of {cell:g} m cells over {hi[0] - lo[0]:.4g} m x {hi[1] - lo[1]:.4g} m",
                     "use larger cells")
        nx, ny = extent.astype(np.int64).tolist()
        n_per_grid = nx * ny
        total = 4 * n_per_grid

        # Sums of squares about the scan's centre, not the sensor, stay well conditioned.
        centre = (lo + hi) / 2.0
        local = pts - centre
        f0 = (pts - origins[0]) / cell  # grid 0 coordinates; the shifted grids are f0 + 0.5
        ia = f0.astype(np.int64)  # f0 >= 1: truncation is floor
        ib = (f0 + 0.5).astype(np.int64)
        keys = np.concatenate((ia[:, 0] * ny + ia[:, 1], ib[:, 0] * ny + ia[:, 1] + n_per_grid,
                               ia[:, 0] * ny + ib[:, 1] + 2 * n_per_grid, ib[:, 0] * ny + ib[:, 1] + 3 * n_per_grid))
        lx = np.tile(local[:, 0], 4)
        ly = np.tile(local[:, 1], 4)
        count = np.bincount(keys, minlength=total)
        valid = np.flatnonzero(count >= MIN_POINTS_PER_CELL)
        n = count[valid].astype(np.float64)
        mx = np.bincount(keys, lx, total)[valid] / n
        my = np.bincount(keys, ly, total)[valid] / n
        # Covariance [[p, q], [q, r]] (1/n normalization, as in the paper).
        p = np.bincount(keys, lx * lx, total)[valid] / n - mx * mx
        q = np.bincount(keys, lx * ly, total)[valid] / n - mx * my
        r = np.bincount(keys, ly * ly, total)[valid] / n - my * my
        # Closed-form eigenvalues; raise the smaller to MIN_EIGENVALUE_RATIO of the larger
        # by adding (raise) * v v^T, v its unit eigenvector: v v^T = (l_max I - Sigma) / (l_max - l_min).
        half_tr = (p + r) / 2.0
        rad = np.sqrt(((p - r) / 2.0) ** 2 + q * q)
        l_max, l_min = half_tr + rad, half_tr - rad
        raise_by = np.maximum(MIN_EIGENVALUE_RATIO * l_max - l_min, 0.0)
        k = np.divide(raise_by, 2.0 * rad, out=np.zeros_like(rad), where=rad > 0)
        p, q, r = p + k * (l_max - p), q - k * q, r + k * (l_max - r)
        # Widen the major axis by the anisotropy: l_min' I + inflation * (Sigma - l_min' I) keeps the minor
        # eigenvalue l_min' and turns the major into l_min' + inflation * (l_max - l_min'): a line-like cell's
        # major variance grows about inflation-fold, a round cell stays round.
        if cell_model == "widened":
            l_min = np.maximum(l_min, MIN_EIGENVALUE_RATIO * l_max)
            keep = (1.0 - MAJOR_AXIS_INFLATION) * l_min
            p, q, r = (RESIDUAL_COVARIANCE_FACTOR * (MAJOR_AXIS_INFLATION * p + keep),
                       RESIDUAL_COVARIANCE_FACTOR * MAJOR_AXIS_INFLATION * q,
                       RESIDUAL_COVARIANCE_FACTOR * (MAJOR_AXIS_INFLATION * r + keep))
        det = p * r - q * q
        ok = (l_max > 0) & (det > 0)  # all points of the cell identical: no distribution
        rows = valid[ok]
        table = np.zeros((6, total))
        table[_MX, rows] = mx[ok] + centre[0]
        table[_MY, rows] = my[ok] + centre[1]
        table[_IA, rows] = r[ok] / det[ok]
        table[_IB, rows] = -q[ok] / det[ok]
        table[_IC, rows] = p[ok] / det[ok]
        table[_W, rows] = 1.0
        return cls(
            cell_size=cell, n_points=len(pts), n_cells=len(rows),
            origins=origins, shape=(nx, ny), table=table,
            clip_hi=np.array([[nx - 1.5], [ny - 1.5]]), grid_bases=(np.arange(4, dtype=np.intp) * n_per_grid)[:, None],
        )

    def lookup(self, xy: np.ndarray) -> np.ndarray:
        """Cells of points xy (2, N) (metres, reference frame) in the four grids: (6, 4, N) planes of ``table``.

        Points outside the grids land in empty border cells (weight 0).
        """
        # Grid-0 coordinates, clipped so that the half-cell-shifted ones stay inside too.
        f = np.minimum(np.maximum((xy - self.origins[0][:, None]) * (1.0 / self.cell_size), 0.0), self.clip_hi)
        shifted = np.empty((2, 2, f.shape[1]))  # (shift, axis, N)
        shifted[0] = f
        np.add(f, 0.5, out=shifted[1])
        i = shifted.astype(np.intp)
        keys = i[_SHIFT_X, 0] * self.shape[1] + i[_SHIFT_Y, 1] + self.grid_bases
        return self.table.take(keys, axis=1)


# Grid g is shifted by half a cell in x when g is 1 or 3, in y when g is 2 or 3.
_SHIFT_X = np.array([0, 1, 0, 1])
_SHIFT_Y = np.array([0, 0, 1, 1])


def voxel_mean(points: np.ndarray, voxel_m: float) -> np.ndarray:
    """One point (the mean) per square voxel of side ``voxel_m`` of (N,2) ``points`` (m): near walls, where a
    scanner's beams crowd, stop outweighing the far features that tell one place in a corridor from the next."""
    if voxel_m <= 0 or len(points) == 0:
        return points
    keys = np.floor(points / voxel_m).astype(np.int64)
    _, voxel, counts = np.unique(keys[:, 0] * 4_000_037 + keys[:, 1], return_inverse=True, return_counts=True)
    sums = np.zeros((counts.size, 2))
    np.add.at(sums, voxel.reshape(-1), points)
    return sums / counts[:, None]
