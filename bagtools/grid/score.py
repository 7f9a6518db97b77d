"""Scoring a built map against the true world rasterized at the same geometry.

The truth is given as two boolean grids, so this module does not depend on
where it comes from; :func:`rasterize_truth` builds them from any world that can
answer "how far is this point from an obstacle surface" and "how much clearance
does this point have" (the simulator's ``World.surface_distance_2d_m`` and
``World.clearance_m``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass

import numpy as np

from bagtools.grid.occupancy import OccupancyGrid


def rasterize_truth(
    grid: OccupancyGrid,
    surface_distance_m: Callable[[np.ndarray], np.ndarray],
    clearance_m: Callable[[np.ndarray], np.ndarray],
) -> tuple[np.ndarray, np.ndarray]:
    """The true world at ``grid``'s geometry: (truly_occupied, truly_free), (rows, cols) bool, row 0 top.

    A cell is truly occupied when an obstacle surface comes within half a cell
    diagonal of its centre (every cell a surface passes through, plus cells it
    nearly touches); truly free when its centre has more clearance than half a
    cell diagonal (the whole cell is in free space). Cells near a surface are
    neither, as are cells inside obstacles.

    Args:
        grid: gives the geometry (its contents are not used).
        surface_distance_m: (N, 2) world [x y] -> (N,) unsigned distance to the nearest surface, metres.
        clearance_m: (N, 2) world [x y] -> (N,) clearance, metres; < 0 inside obstacles or outside the free interior.
    """
    centres = grid.cell_centers()
    rows, cols = grid.grid_size
    flat = centres.reshape(-1, 2)
    half_diagonal = grid.cell_size_m * np.sqrt(0.5)
    surface = np.abs(np.asarray(surface_distance_m(flat), dtype=np.float64)).reshape(rows, cols)
    clearance = np.asarray(clearance_m(flat), dtype=np.float64).reshape(rows, cols)
    return surface <= half_diagonal, clearance > half_diagonal


@dataclass(frozen=True)
class MapScore:
    """How a map agrees with the truth.

    ``occupied_precision``: share of cells the map calls occupied that lie within
    ``tolerance_cells`` of a truly occupied cell. ``occupied_recall``: share of
    truly occupied cells with a map-occupied cell within the tolerance.
    ``free_share``: share of truly free cells the map calls free.
    ``free_marked_occupied``: share of truly free cells the map calls occupied and
    that are farther than the tolerance from any truly occupied cell (phantom obstacles).
    Shares are NaN when their denominator is zero.
    """

    occupied_precision: float
    occupied_recall: float
    free_share: float
    free_marked_occupied: float
    map_occupied_cells: int
    true_occupied_cells: int
    true_free_cells: int
    tolerance_cells: int

    def to_dict(self) -> dict:
        """A JSON-ready dict (NaN shares become None)."""
        return {k: (None if isinstance(v, float) and np.isnan(v) else v) for k, v in asdict(self).items()}


def _share(numerator: int, denominator: int) -> float:
    return numerator / denominator if denominator else float("nan")


def score_map(
    map_ternary: np.ndarray, truly_occupied: np.ndarray, truly_free: np.ndarray, tolerance_cells: int = 1,
) -> MapScore:
    """Compare a map's classes with the truth at the same geometry.

    Args:
        map_ternary: (rows, cols) classes: 1 occupied, 0 free, -1 unknown
            (``OccupancyGrid.occupancy_matrix('ternary')`` or ``Nav2Map.ternary()``).
        truly_occupied, truly_free: (rows, cols) bool truth, same layout.
        tolerance_cells: how far (Chebyshev distance, cells) an occupied cell may be
            from its counterpart and still count.
    """
    map_ternary = np.asarray(map_ternary)
    truly_occupied = np.asarray(truly_occupied, dtype=bool)
    truly_free = np.asarray(truly_free, dtype=bool)
    if not (map_ternary.shape == truly_occupied.shape == truly_free.shape) or map_ternary.ndim != 2:
        raise ValueError(
            f"map and truth must be 2-D grids of one shape, got {map_ternary.shape}, "
            f"{truly_occupied.shape}, {truly_free.shape}")
    if tolerance_cells < 0:
        raise ValueError(f"tolerance_cells must be >= 0, got {tolerance_cells}")
    from scipy.ndimage import binary_dilation  # here, not at import: every command that maps imports this module

    occupied = map_ternary == 1
    free = map_ternary == 0
    square = np.ones((3, 3), dtype=bool)

    def near(mask: np.ndarray) -> np.ndarray:
        return binary_dilation(mask, square, iterations=tolerance_cells) if tolerance_cells else mask

    near_truth = near(truly_occupied)
    near_map = near(occupied)
    n_occ, n_true_occ, n_free = int(occupied.sum()), int(truly_occupied.sum()), int(truly_free.sum())
    return MapScore(
        occupied_precision=_share(int((occupied & near_truth).sum()), n_occ),
        occupied_recall=_share(int((truly_occupied & near_map).sum()), n_true_occ),
        free_share=_share(int((truly_free & free).sum()), n_free),
        free_marked_occupied=_share(int((truly_free & occupied & ~near_truth).sum()), n_free),
        map_occupied_cells=n_occ,
        true_occupied_cells=n_true_occ,
        true_free_cells=n_free,
        tolerance_cells=int(tolerance_cells),
    )
