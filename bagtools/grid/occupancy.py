"""A probabilistic 2-D occupancy grid in log-odds, with MATLAB occupancyMap conventions.

Geometry: the grid covers a rectangle of the world frame whose bottom-left
corner is :attr:`OccupancyGrid.grid_location_in_world`; ``resolution`` is in
cells per metre. Grid indices are ``[row, col]`` **0-based** (MATLAB's are
1-based) with row 0 at the *top* (largest y), so the matrices returned here are
laid out like the map image. A world point belongs to the cell whose lower/left
edges it lies on (floor; within 1e-9 cells of an edge counts as on it), except
that points on the grid's top and right outer edges belong to the last row/column.

Updates follow MATLAB's ``insertRay``: cells a beam passes through get the free
observation (default 0.4), the cell it ends in the occupied observation (0.7);
a range at or beyond ``max_range`` marks the cells up to ``max_range`` free and
nothing occupied; NaN ranges are ignored; negative ranges are an error.
Probabilities saturate at [0.001, 0.999]; a cell is occupied above 0.65, free
below 0.20, unknown otherwise; never-observed cells are 0.5.

Several beams of one scan: each cell receives **at most one update per
insert_ray call** - the occupied observation if any beam ends in it, otherwise
the free observation if any beam passes through it (as OctoMap's
insertPointCloud does). Beams of one scan are not independent evidence about the
cells near the sensor, and letting an end point win over the neighbouring beams
that graze the same wall cell keeps walls seen at shallow angles from being
erased by their own scan. One beam alone gives exactly MATLAB's per-ray update.

The grid grows when data falls outside it: existing cells keep their world
position; new cells are unknown.
"""

from __future__ import annotations

import math

import numpy as np

from bagtools.grid.raytrace import EPS_CELLS, Workspace, segment_batch, window_cells

#: Cells traversed at once by :meth:`OccupancyGrid.insert_ray` (a few hundred MB of traversal): a scan whose rays
#: cross more (a 20-million-beam scan) is inserted in parts, each part's cells updated once.
RAY_CELLS_PER_PART = 2_000_000

GROW_STEP_CELLS = 32
"""When the grid grows, each side grows by a multiple of this many cells."""

DEFAULT_INVERSE_MODEL = (0.4, 0.7)
"""MATLAB insertRay's default [free occupied] observation probabilities."""


def _logit(p: float) -> float:
    return math.log(p / (1.0 - p))


def _as_points(points: np.ndarray, name: str) -> np.ndarray:
    arr = np.asarray(points, dtype=np.float64)
    if arr.ndim == 1 and arr.shape[0] == 2:
        arr = arr[None, :]
    if arr.ndim != 2 or arr.shape[1] != 2:
        raise ValueError(f"{name} must be (N, 2), got shape {np.shape(points)}")
    return arr


class OccupancyGrid:
    """Log-odds occupancy grid over a growing rectangle of the world frame.

    Args:
        width_m, height_m: extent in metres (rounded up to whole cells).
        resolution: cells per metre (20 means 5 cm cells).
        grid_location_in_world: world [x y] of the bottom-left corner, metres.
        occupied_threshold: probability above which a cell is occupied.
        free_threshold: probability below which a cell is free.
        probability_saturation: [min max] probabilities a cell can reach.
    """

    def __init__(
        self,
        width_m: float,
        height_m: float,
        resolution: float,
        grid_location_in_world: tuple[float, float] | np.ndarray = (0.0, 0.0),
        *,
        occupied_threshold: float = 0.65,
        free_threshold: float = 0.20,
        probability_saturation: tuple[float, float] = (0.001, 0.999),
    ) -> None:
        if not (np.isfinite(resolution) and resolution > 0):
            raise ValueError(f"resolution must be a positive number of cells per metre, got {resolution}")
        if not (np.isfinite(width_m) and np.isfinite(height_m) and width_m > 0 and height_m > 0):
            raise ValueError(f"width and height must be positive metres, got {width_m} x {height_m}")
        loc = np.asarray(grid_location_in_world, dtype=np.float64).reshape(-1)
        if loc.shape != (2,) or not np.all(np.isfinite(loc)):
            raise ValueError(f"grid_location_in_world must be a finite [x y], got {grid_location_in_world}")
        lo_p, hi_p = (float(p) for p in probability_saturation)
        if not 0.0 < lo_p < 0.5 < hi_p < 1.0:
            raise ValueError(f"probability_saturation must satisfy 0 < min < 0.5 < max < 1, got {probability_saturation}")
        if not 0.0 < free_threshold <= occupied_threshold < 1.0:
            raise ValueError(
                f"thresholds must satisfy 0 < free <= occupied < 1, got free {free_threshold}, occupied {occupied_threshold}")
        self._res = float(resolution)
        self._anchor = loc.copy()
        # global cell index (relative to the anchor) of the array's bottom-left cell
        self._off_col = 0
        self._off_row = 0
        cols = max(1, math.ceil(width_m * self._res - 1e-9))
        rows = max(1, math.ceil(height_m * self._res - 1e-9))
        self._log_odds = np.zeros((rows, cols), dtype=np.float32)
        self.occupied_threshold = float(occupied_threshold)
        self.free_threshold = float(free_threshold)
        self.probability_saturation = (lo_p, hi_p)
        self._l_min, self._l_max = _logit(lo_p), _logit(hi_p)
        self._work = Workspace()  # insert_ray's work arrays, reused scan to scan

    @classmethod
    def from_probabilities(
        cls, probabilities: np.ndarray, resolution: float,
        grid_location_in_world: tuple[float, float] | np.ndarray = (0.0, 0.0), **kwargs,
    ) -> OccupancyGrid:
        """A grid holding the given (rows, cols) probabilities (row 0 at the top), saturated."""
        p = np.asarray(probabilities, dtype=np.float64)
        if p.ndim != 2 or p.size == 0 or np.any(~np.isfinite(p)) or np.any((p < 0) | (p > 1)):
            raise ValueError("probabilities must be a non-empty 2-D array of values in [0, 1]")
        grid = cls(p.shape[1] / resolution, p.shape[0] / resolution, resolution, grid_location_in_world, **kwargs)
        lo, hi = grid.probability_saturation
        pc = np.clip(p, lo, hi)
        grid._log_odds[...] = np.log(pc / (1.0 - pc))
        return grid

    # ---- geometry -------------------------------------------------------------------

    @property
    def resolution(self) -> float:
        """Cells per metre."""
        return self._res

    @property
    def cell_size_m(self) -> float:
        """Edge length of a cell, metres."""
        return 1.0 / self._res

    @property
    def grid_size(self) -> tuple[int, int]:
        """(rows, cols)."""
        return self._log_odds.shape  # type: ignore[return-value]

    @property
    def grid_location_in_world(self) -> np.ndarray:
        """World [x y] of the grid's bottom-left corner, metres."""
        return self._anchor + np.array([self._off_col, self._off_row], dtype=np.float64) / self._res

    @property
    def x_world_limits(self) -> tuple[float, float]:
        """[min max] world x covered, metres."""
        x0 = float(self._anchor[0] + self._off_col / self._res)
        return x0, float(self._anchor[0] + (self._off_col + self._log_odds.shape[1]) / self._res)

    @property
    def y_world_limits(self) -> tuple[float, float]:
        """[min max] world y covered, metres."""
        y0 = float(self._anchor[1] + self._off_row / self._res)
        return y0, float(self._anchor[1] + (self._off_row + self._log_odds.shape[0]) / self._res)

    @property
    def log_odds(self) -> np.ndarray:
        """The (rows, cols) log-odds matrix, row 0 at the top (a read-only view)."""
        view = self._log_odds.view()
        view.flags.writeable = False
        return view

    def _world_to_uv(self, xy: np.ndarray) -> np.ndarray:
        """World metres -> global grid units (relative to the fixed anchor)."""
        return (xy - self._anchor) * self._res

    def world2grid(self, xy: np.ndarray) -> np.ndarray:
        """World points (N, 2) [x y] metres -> (N, 2) int [row col] grid indices (0-based, row 0 top).

        Points outside the grid give indices outside [0, rows) x [0, cols); use
        :meth:`contains` to test.
        """
        xy = _as_points(xy, "xy")
        # points within rounding noise (EPS_CELLS) of a cell edge count as on it
        uv = self._world_to_uv(xy) + EPS_CELLS
        rows, cols = self._log_odds.shape
        col = np.floor(uv[:, 0]).astype(np.int64) - self._off_col
        up = np.floor(uv[:, 1]).astype(np.int64) - self._off_row
        # the outer top/right edges belong to the last column/row
        col[(col == cols) & (uv[:, 0] < self._off_col + cols + 2 * EPS_CELLS)] = cols - 1
        up[(up == rows) & (uv[:, 1] < self._off_row + rows + 2 * EPS_CELLS)] = rows - 1
        return np.stack([rows - 1 - up, col], axis=1)

    def grid2world(self, ij: np.ndarray) -> np.ndarray:
        """Grid indices (N, 2) [row col] (0-based, row 0 top) -> world [x y] of the cell centres, metres."""
        ij = np.asarray(ij)
        if ij.ndim == 1 and ij.shape[0] == 2:
            ij = ij[None, :]
        if ij.ndim != 2 or ij.shape[1] != 2:
            raise ValueError(f"ij must be (N, 2), got shape {np.shape(ij)}")
        rows = self._log_odds.shape[0]
        u = ij[:, 1] + self._off_col + 0.5
        v = (rows - 1 - ij[:, 0]) + self._off_row + 0.5
        return self._anchor + np.stack([u, v], axis=1) / self._res

    def cell_centers(self) -> np.ndarray:
        """World [x y] of every cell centre as a (rows, cols, 2) array, row 0 at the top."""
        rows, cols = self._log_odds.shape
        x = self._anchor[0] + (np.arange(cols) + self._off_col + 0.5) / self._res
        y = self._anchor[1] + (np.arange(rows)[::-1] + self._off_row + 0.5) / self._res
        return np.stack(np.meshgrid(x, y), axis=-1)

    def _inside(self, ij: np.ndarray) -> np.ndarray:
        rows, cols = self._log_odds.shape
        return (ij[:, 0] >= 0) & (ij[:, 0] < rows) & (ij[:, 1] >= 0) & (ij[:, 1] < cols)

    def contains(self, xy: np.ndarray) -> np.ndarray:
        """(N,) bool: which world points [x y] lie in the grid (outer edges included)."""
        return self._inside(self.world2grid(xy))

    # ---- reading --------------------------------------------------------------------

    def _locations_to_ij(self, locations: np.ndarray, frame: str) -> np.ndarray:
        if frame == "world":
            return self.world2grid(locations)
        if frame == "grid":
            ij = np.asarray(locations)
            if ij.ndim == 1 and ij.shape[0] == 2:
                ij = ij[None, :]
            if ij.ndim != 2 or ij.shape[1] != 2 or not np.issubdtype(ij.dtype, np.integer):
                raise ValueError("grid locations must be an integer (N, 2) array of [row col]")
            return ij
        raise ValueError(f"frame must be 'world' or 'grid', got {frame!r}")

    def get_occupancy(self, locations: np.ndarray, frame: str = "world") -> np.ndarray:
        """Occupancy probabilities (N,) at world [x y] points, or at [row col] cells with frame='grid'.

        Locations outside the grid read 0.5 (unknown).
        """
        ij = self._locations_to_ij(locations, frame)
        inside = self._inside(ij)
        out = np.full(ij.shape[0], 0.5)
        logit = self._log_odds[ij[inside, 0], ij[inside, 1]].astype(np.float64)
        out[inside] = 1.0 / (1.0 + np.exp(-logit))
        return out

    def _classify(self, p: np.ndarray) -> np.ndarray:
        out = np.full(p.shape, -1, dtype=np.int8)
        out[p > self.occupied_threshold] = 1
        out[p < self.free_threshold] = 0
        return out

    def check_occupancy(self, locations: np.ndarray, frame: str = "world") -> np.ndarray:
        """(N,) int8: 1 occupied (p > occupied_threshold), 0 free (p < free_threshold), -1 unknown.

        Locations outside the grid are -1.
        """
        return self._classify(self.get_occupancy(locations, frame))

    def occupancy_matrix(self, kind: str = "probability") -> np.ndarray:
        """The whole grid, row 0 at the top: probabilities (float64), or with
        kind='ternary' the int8 classes 1 occupied / 0 free / -1 unknown."""
        p = self._log_odds.astype(np.float64)  # the one full-size array: 1 / (1 + exp(-l)) computed in place
        np.negative(p, out=p)
        np.exp(p, out=p)
        p += 1.0
        np.reciprocal(p, out=p)
        if kind == "probability":
            return p
        if kind == "ternary":
            return self._classify(p)
        raise ValueError(f"kind must be 'probability' or 'ternary', got {kind!r}")

    # ---- growing --------------------------------------------------------------------

    def _grow_to_cells(self, col_min: int, row_min: int, col_max: int, row_max: int) -> None:
        """Grow so that global cells [col_min, col_max] x [row_min, row_max] (rows upward) exist."""
        rows, cols = self._log_odds.shape
        step = GROW_STEP_CELLS

        def pad(needed: int) -> int:
            return 0 if needed <= 0 else -(-needed // step) * step

        left = pad(self._off_col - col_min)
        right = pad(col_max - (self._off_col + cols - 1))
        bottom = pad(self._off_row - row_min)
        top = pad(row_max - (self._off_row + rows - 1))
        if left or right or bottom or top:
            self._log_odds = np.pad(self._log_odds, ((top, bottom), (left, right)))
            self._off_col -= left
            self._off_row -= bottom

    def grow_to_include(self, xy: np.ndarray) -> None:
        """Grow the grid (keeping every existing cell at its world position) to contain world points [x y]."""
        xy = _as_points(xy, "xy")
        if xy.shape[0] == 0:
            return
        if not np.all(np.isfinite(xy)):
            raise ValueError("points must be finite")
        uv = np.floor(self._world_to_uv(xy))
        lo, hi = uv.min(axis=0), uv.max(axis=0)
        self._grow_to_cells(int(lo[0]), int(lo[1]), int(hi[0]), int(hi[1]))

    # ---- updating -------------------------------------------------------------------

    def _inverse_model_log_odds(self, inverse_model: tuple[float, float]) -> tuple[float, float]:
        try:
            p_free, p_occ = (float(p) for p in inverse_model)
        except (TypeError, ValueError):
            raise ValueError(f"inverse_model must be [free occupied] probabilities, got {inverse_model!r}") from None
        if not 0.0 < p_free < 0.5 < p_occ < 1.0:
            raise ValueError(f"inverse_model must satisfy 0 < free < 0.5 < occupied < 1, got {inverse_model!r}")
        return _logit(p_free), _logit(p_occ)

    def insert_ray(
        self,
        pose: np.ndarray,
        ranges: np.ndarray,
        angles: np.ndarray,
        max_range: float,
        inverse_model: tuple[float, float] = DEFAULT_INVERSE_MODEL,
    ) -> None:
        """Integrate one range scan taken from ``pose``.

        Args:
            pose: sensor [x y theta] in the grid's world frame (metres, rad).
            ranges: (N,) metres; NaN and -inf (REP 117: closer than the sensor's minimum) ignored,
                >= max_range (or inf) is a free beam up to max_range.
            angles: (N,) beam angles in the sensor frame, rad.
            max_range: the sensor's maximum range, metres.
            inverse_model: [free occupied] observation probabilities.

        Raises:
            ValueError: negative finite ranges, mismatched shapes, non-finite pose/angles/max_range.
        """
        pose = np.asarray(pose, dtype=np.float64).reshape(-1)
        if pose.shape != (3,) or not all(map(math.isfinite, pose.tolist())):
            raise ValueError(f"pose must be a finite [x y theta], got {pose!r}")
        ranges = np.asarray(ranges, dtype=np.float64).reshape(-1)
        angles = np.asarray(angles, dtype=np.float64).reshape(-1)
        if ranges.shape != angles.shape:
            raise ValueError(f"ranges and angles differ in length: {ranges.size} vs {angles.size}")
        if not (np.isfinite(max_range) and max_range > 0):
            raise ValueError(f"max_range must be a positive number of metres, got {max_range}")
        # one reduction each in the common case: no NaN, -inf or negative range; finite angles
        lowest = ranges.min() if ranges.size else 0.0
        if not lowest >= 0.0 and np.any((ranges < 0) & np.isfinite(ranges)):
            raise ValueError(f"ranges must not be negative (min {np.nanmin(ranges[np.isfinite(ranges)])} m)")
        if not np.isfinite(angles.sum()) and not np.all(np.isfinite(angles)):
            raise ValueError("angles must be finite")
        l_free, l_occ = self._inverse_model_log_odds(inverse_model)
        if not lowest > -np.inf:  # NaN or -inf present
            valid = ~np.isnan(ranges) & (ranges != -np.inf)
            ranges, angles = ranges[valid], angles[valid]
        if ranges.size == 0:
            return
        hit = ranges < max_range
        r = np.minimum(ranges, max_range)
        # beam ends in grid units, (2, N): ((pose + r*[cos sin]) - anchor) * resolution
        world_angles = angles + pose[2]
        ends_uv = np.empty((2, r.size))
        np.cos(world_angles, out=ends_uv[0])
        np.sin(world_angles, out=ends_uv[1])
        ends_uv *= r
        ends_uv += pose[:2, None]
        ends_uv -= self._anchor[:, None]
        ends_uv *= self._res
        start_uv = self._world_to_uv(pose[:2])
        # A scan of millions of beams is traversed in parts of RAY_CELLS_PER_PART cells, not all at once
        # (a scan that cannot reach that many, even at max_range everywhere, is one part).
        if r.size * (max_range * self._res + 2.0) < 0.999 * RAY_CELLS_PER_PART:
            self._insert(start_uv, ends_uv, hit, l_free, l_occ)
            return
        crossed = np.cumsum(r * self.resolution + 2.0)
        cuts = np.searchsorted(crossed, np.arange(RAY_CELLS_PER_PART, crossed[-1], RAY_CELLS_PER_PART))
        for part in np.split(np.arange(r.size), np.unique(cuts)):
            if part.size:
                self._insert(start_uv, ends_uv[:, part], hit[part], l_free, l_occ)

    def insert_segments(
        self, start_xy: np.ndarray, end_xy: np.ndarray, inverse_model: tuple[float, float] = DEFAULT_INVERSE_MODEL,
    ) -> None:
        """MATLAB's ``insertRay(map, startpt, endpoints)``: free along start -> each end, occupied at each end.

        Args:
            start_xy: world [x y] of the common start, metres.
            end_xy: (N, 2) world end points, metres.
            inverse_model: [free occupied] observation probabilities.
        """
        start = np.asarray(start_xy, dtype=np.float64).reshape(-1)
        ends = _as_points(end_xy, "end_xy")
        if start.shape != (2,) or not np.all(np.isfinite(start)) or not np.all(np.isfinite(ends)):
            raise ValueError("start and end points must be finite [x y]")
        l_free, l_occ = self._inverse_model_log_odds(inverse_model)
        if ends.shape[0]:
            self._insert(self._world_to_uv(start), self._world_to_uv(ends).T, np.ones(ends.shape[0], dtype=bool),
                         l_free, l_occ)

    def _insert(self, start_uv: np.ndarray, ends_uv: np.ndarray, hit: np.ndarray, l_free: float, l_occ: float) -> None:
        """Update the cells of segments start_uv (2,) -> ends_uv (2, N), grid units; hit: (N,) bool, ends occupied."""
        seg = segment_batch(start_uv, ends_uv)
        # every visited cell lies in the box spanned by the start and end cells
        box = np.concatenate((seg.first, seg.last), axis=1)
        (c_lo, r_lo), (c_hi, r_hi) = box.min(axis=1).astype(int).tolist(), box.max(axis=1).astype(int).tolist()
        self._grow_to_cells(c_lo, r_lo, c_hi, r_hi)
        width, height = c_hi - c_lo + 1, r_hi - r_lo + 1
        # one update per cell: occupied where a beam ends, else free where one passes, else none
        delta = np.zeros(height * width, dtype=np.float32)
        delta[window_cells(seg, c_lo, r_lo, width, height, self._work)] = l_free
        ends = np.dot((1.0, float(width)), seg.last[:, hit] - [[c_lo], [r_lo]])  # exact: small whole numbers
        delta[ends.astype(np.intp)] = l_occ
        rows = self._log_odds.shape[0]
        top = rows - 1 - (r_hi - self._off_row)
        left = c_lo - self._off_col
        window = self._log_odds[top:top + height, left:left + width]
        window += delta.reshape(height, width)[::-1]
        np.clip(window, self._l_min, self._l_max, out=window)

    def cropped(self, margin_cells: int = 10) -> OccupancyGrid:
        """A copy cut down to the observed cells (log-odds != 0) plus ``margin_cells`` of unknown around them.

        Cells keep their world positions. A grid with no observed cell is returned whole.
        """
        observed = self._log_odds != 0
        if not observed.any():
            return self.copy()
        rows_any, cols_any = np.flatnonzero(observed.any(axis=1)), np.flatnonzero(observed.any(axis=0))
        rows, cols = self._log_odds.shape
        top, bottom = max(0, rows_any[0] - margin_cells), min(rows, rows_any[-1] + 1 + margin_cells)
        left, right = max(0, cols_any[0] - margin_cells), min(cols, cols_any[-1] + 1 + margin_cells)
        other = self.copy()
        other._log_odds = self._log_odds[top:bottom, left:right].copy()
        other._off_col = self._off_col + left
        other._off_row = self._off_row + (rows - bottom)
        return other

    def __getstate__(self) -> dict:
        state = self.__dict__.copy()
        state["_work"] = Workspace()  # scratch, not state
        return state

    def copy(self) -> OccupancyGrid:
        """An independent copy."""
        other = object.__new__(OccupancyGrid)
        other.__dict__.update(self.__dict__)
        other._log_odds = self._log_odds.copy()
        other._anchor = self._anchor.copy()
        other._work = Workspace()
        return other

    def __repr__(self) -> str:
        rows, cols = self.grid_size
        x0, y0 = self.grid_location_in_world
        return (f"OccupancyGrid({rows}x{cols} cells, {self.cell_size_m:g} m/cell, "
                f"bottom-left at ({x0:g}, {y0:g}) m)")
