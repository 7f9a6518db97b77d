"""Collision-free routes for the simulated robot: a lap around the pillars, a figure eight, a random tour.

A route is an approach polyline from the spawn point to a closed loop, which the robot then
drives round and round. Coordinates are metres in the map frame. Every route is checked
against ``world.clearance_m`` so that the robot's footprint (a disc of ``robot_radius_m``)
keeps a margin to every obstacle along the whole path.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from bagtools.errors import BagtoolsError
from bagtools_simulate.robot.waffle import ROBOT_RADIUS_M

ROUTE_NAMES = ("lap", "figure8", "random")
PATH_SPACING_M = 0.02
# Clearance kept by the planned path beyond the robot radius; the controller's tracking error must stay below it.
PLANNED_MARGIN_M = 0.10


class ClearanceWorld(Protocol):
    """What a route needs from a world: its spawn pose and 2D clearance to obstacles."""

    name: str
    spawn_xy_yaw: tuple[float, float, float]

    def clearance_m(self, xy: np.ndarray) -> np.ndarray: ...


@dataclass(frozen=True)
class Route:
    """A route: ``approach_xy`` (K, 2) from the spawn to ``loop_xy[0]``, then the closed loop ``loop_xy`` (N, 2)."""

    name: str
    approach_xy: np.ndarray
    loop_xy: np.ndarray

    def path(self, min_length_m: float) -> np.ndarray:
        """A dense polyline (M, 2): the approach, then the loop repeated until at least ``min_length_m`` long."""
        closed = np.vstack([self.loop_xy, self.loop_xy[:1]])
        loop_len = float(np.linalg.norm(np.diff(closed, axis=0), axis=1).sum())
        laps = max(1, int(np.ceil(min_length_m / loop_len)) + 1)
        parts = [self.approach_xy[:-1], np.tile(self.loop_xy, (laps, 1)), self.loop_xy[:1]]
        return densify(np.vstack(parts), PATH_SPACING_M)


def densify(xy: np.ndarray, spacing_m: float) -> np.ndarray:
    """Resample the polyline ``xy`` (N, 2) so that consecutive points are at most ``spacing_m`` apart."""
    xy = np.asarray(xy, dtype=np.float64)
    if len(xy) < 2:
        return xy.copy()
    seg = np.diff(xy, axis=0)
    n_sub = np.maximum(1, np.ceil(np.linalg.norm(seg, axis=1) / spacing_m).astype(int))
    seg_index = np.repeat(np.arange(len(seg)), n_sub)
    frac = np.concatenate([np.arange(n) / n for n in n_sub])
    out = xy[seg_index] + frac[:, None] * seg[seg_index]
    return np.vstack([out, xy[-1:]])


def min_path_clearance_m(world: ClearanceWorld, xy: np.ndarray) -> float:
    """The smallest clearance (m) of the polyline ``xy`` sampled every few centimetres."""
    return float(np.min(world.clearance_m(densify(xy, PATH_SPACING_M))))


def _superellipse_lap() -> np.ndarray:
    # A rounded square (superellipse, exponent 3) around the 3x3 pillar grid of the TurtleBot3
    # world, driven counter-clockwise: keeps ~0.37 m from pillars, the hexagons and the shell.
    t = np.linspace(0.0, 2.0 * np.pi, 360, endpoint=False)
    c, s = np.cos(t), np.sin(t)
    return np.column_stack([1.9 * np.sign(c) * np.abs(c) ** (2 / 3), 1.85 * np.sign(s) * np.abs(s) ** (2 / 3)])


def _figure_eight() -> np.ndarray:
    # A lemniscate of Gerono along the diagonal, crossing between four pillars at (-0.55, 0.55),
    # each lobe circling one pillar; ~0.34 m from every obstacle in the TurtleBot3 world.
    t = np.linspace(0.0, 2.0 * np.pi, 360, endpoint=False)
    x, y = 1.3 * np.sin(t), 1.2 * np.sin(t) * np.cos(t)
    c = s = np.sqrt(0.5)
    return np.column_stack([-0.55 + c * x - s * y, 0.55 + s * x + c * y])


def _join(world: ClearanceWorld, loop_xy: np.ndarray, name: str, robot_radius_m: float) -> Route:
    spawn = np.asarray(world.spawn_xy_yaw[:2], dtype=np.float64)
    start = int(np.argmin(np.linalg.norm(loop_xy - spawn, axis=1)))
    loop_xy = np.roll(loop_xy, -start, axis=0)
    approach = np.vstack([spawn, loop_xy[:1]])
    route = Route(name, approach, loop_xy)
    needed = robot_radius_m + PLANNED_MARGIN_M
    closed = np.vstack([approach, loop_xy, loop_xy[:1]])
    if min_path_clearance_m(world, closed) < needed:
        raise BagtoolsError(
            f"route {name!r} does not keep {needed:.2f} m from obstacles in world {world.name!r}; try --route random"
        )
    return route


def _random_tour(world: ClearanceWorld, seed: int, robot_radius_m: float, n_waypoints: int = 8) -> Route:
    """A closed tour from the spawn through ``n_waypoints`` free points drawn with ``seed``."""
    rng = np.random.default_rng([seed, 0x7A11])
    needed = robot_radius_m + PLANNED_MARGIN_M + 0.05
    spawn = np.asarray(world.spawn_xy_yaw[:2], dtype=np.float64)
    # Candidate points: a seeded uniform sample of the bounding box of free space near the spawn.
    probe = spawn + rng.uniform(-6.0, 6.0, size=(20000, 2))
    free = probe[world.clearance_m(probe) >= needed + 0.05]
    if len(free) < n_waypoints:
        raise BagtoolsError(f"too little free space around the spawn point in world {world.name!r}")
    for _attempt in range(200):
        tour = [spawn]
        for _ in range(400):
            if len(tour) > n_waypoints:
                break
            cand = free[rng.integers(len(free))]
            length = np.linalg.norm(cand - tour[-1])
            if 0.8 <= length <= 3.5 and min_path_clearance_m(world, np.vstack([tour[-1], cand])) >= needed:
                tour.append(cand)
        if len(tour) > n_waypoints and min_path_clearance_m(world, np.vstack([tour[-1], spawn])) >= needed:
            loop = np.vstack(tour)
            return Route("random", np.vstack([spawn, spawn]), loop)
    raise BagtoolsError(f"could not find a collision-free random tour in world {world.name!r}")


def make_route(name: str, world: ClearanceWorld, seed: int = 0, robot_radius_m: float = ROBOT_RADIUS_M) -> Route:
    """Build route ``name`` (one of ROUTE_NAMES) in ``world``; ``seed`` only matters for ``random``."""
    if name == "lap":
        return _join(world, _superellipse_lap(), name, robot_radius_m)
    if name == "figure8":
        return _join(world, _figure_eight(), name, robot_radius_m)
    if name == "random":
        return _random_tour(world, seed, robot_radius_m)
    raise BagtoolsError(f"unknown route {name!r} (choose from {', '.join(ROUTE_NAMES)})")
