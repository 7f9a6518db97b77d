"""Where a local map's laser rays passed: the free space two matched maps must not contradict.

A scan match scores how many of one map's points land on the other's walls.
It does not ask whether they land where the other map's laser *saw through*.
A look-alike can score as well as the place: the same corridor a few metres
along, a room of the same shape, a wall that lines up by chance. But there,
one map's walls stand in the other's open space. The place itself contradicts
neither map, except where the world changed between the two visits: a door
shut, a person passing.

:class:`FreeSpace` holds the cells each map's rays crossed. It leaves out the
last ``margin_m`` before each return: range noise, a wall's own cells, and
the error a match may still have. It also holds the cells its returns fell
in, widened by one cell. :meth:`FreeSpace.seen_through` is the share of
another map's points that fall where this one saw through.

The rays start at the robot base (keyframe points are in its frame). The
laser mount's few centimetres to decimetres only shift the rays' start,
inside the robot's own footprint, and the rays meet the true ones at their
returns.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bagtools.grid import traverse

#: The last part of each ray (m) that is not counted as seen free: range noise, the wall's cells and a match's
#: remaining error (the loop search's NDT refinement may move a match this far, ``LoopOptions.max_refine_m``).
FREE_MARGIN_M = 0.3


@dataclass(frozen=True)
class FreeSpace:
    """Cells of side ``resolution_m`` a local map's rays crossed (``free``) and its returns fell in, widened by
    one cell (``occupied``); cell (i, j) has its corner at ``corner + (i, j) * resolution_m`` (map frame, m)."""

    corner: np.ndarray
    resolution_m: float
    free: np.ndarray
    occupied: np.ndarray

    @classmethod
    def from_scans(cls, scans: list[tuple[np.ndarray, np.ndarray]], resolution_m: float,
                   margin_m: float = FREE_MARGIN_M) -> FreeSpace:
        """The free space of ``scans``: (origin (2,), points (N,2)) pairs, the rays' start and returns in one frame
        (m)."""
        origins = np.vstack([np.broadcast_to(np.asarray(o, dtype=np.float64), (len(p), 2)) for o, p in scans]
                            + [np.zeros((0, 2))])
        points = np.vstack([np.asarray(p, dtype=np.float64).reshape(-1, 2) for _, p in scans] + [np.zeros((0, 2))])
        if not len(points):
            return cls(np.zeros(2), resolution_m, np.zeros((1, 1), bool), np.zeros((1, 1), bool))
        ray = points - origins
        length = np.hypot(ray[:, 0], ray[:, 1])
        keep = length > margin_m
        ends = origins[keep] + ray[keep] * ((length[keep] - margin_m) / length[keep])[:, None]
        corner = np.minimum(points.min(axis=0), origins.min(axis=0)) - resolution_m
        shape = tuple(np.floor((np.maximum(points.max(axis=0), origins.max(axis=0)) - corner) / resolution_m)
                      .astype(np.int64) + 2)
        free = np.zeros(shape, bool)
        if len(ends):
            cells = traverse((origins[keep] - corner) / resolution_m, (ends - corner) / resolution_m)
            free[cells.cols, cells.rows] = True
        hit = np.floor((points - corner) / resolution_m).astype(np.int64)
        occupied = np.zeros(shape, bool)
        occupied[hit[:, 0], hit[:, 1]] = True
        widened = occupied.copy()
        widened[1:] |= occupied[:-1]
        widened[:-1] |= occupied[1:]
        widened[:, 1:] |= occupied[:, :-1]
        widened[:, :-1] |= occupied[:, 1:]
        return cls(corner, resolution_m, free, widened)

    def seen_through(self, points: np.ndarray) -> float:
        """Share of ``points`` (N,2, this map's frame) in cells this map saw free and no return of its own fell
        near: 0 when the two agree; 0 for no points."""
        points = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        if not len(points):
            return 0.0
        cell = np.floor((points - self.corner) / self.resolution_m).astype(np.int64)
        inside = (cell >= 0).all(axis=1) & (cell[:, 0] < self.free.shape[0]) & (cell[:, 1] < self.free.shape[1])
        i, j = cell[inside, 0], cell[inside, 1]
        return float(np.count_nonzero(self.free[i, j] & ~self.occupied[i, j])) / len(points)

