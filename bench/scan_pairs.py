"""Synthetic LDS-01 scan pairs for the NDT tests and benchmark.

A minimal 2D ray caster over the TurtleBot3 world outline
(``simulate/data/turtlebot3_world.json``: the hexagonal wall and the nine
pillars): 360 beams over 0..2pi, ranges 0.12-3.5 m, Gaussian range noise of
sd 0.01 m, ``inf`` where a beam returns nothing. A pair is two scans taken from
nearby poses (up to ~0.1 m and ~0.1 rad apart, as between two 5 Hz scans).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

WORLD_JSON = Path(__file__).resolve().parents[1] / "simulate" / "data" / "turtlebot3_world.json"
N_BEAMS = 360
RANGE_MIN_M = 0.12
RANGE_MAX_M = 3.5
NOISE_SD_M = 0.01
ANGLES_RAD = np.arange(N_BEAMS) * (2 * np.pi / N_BEAMS)


@dataclass(frozen=True)
class World2D:
    """Wall segments (S, 2) start/end points and circles (C, 2) centres with radii (C,), metres."""

    seg_start: np.ndarray
    seg_end: np.ndarray
    circle_centres: np.ndarray
    circle_radii: np.ndarray
    free_polygon: np.ndarray  # the inner wall ring, (K, 2)


@lru_cache(maxsize=1)
def turtlebot3_world() -> World2D:
    """The TurtleBot3 world as segments and circles, read from the simulator's JSON."""
    data = json.loads(WORLD_JSON.read_text())
    rings = [np.asarray(data["shell_wall"]["inner"], float)]
    rings += [np.asarray(h["vertices"], float) for h in data["hexagon_obstacles"]]
    starts = np.concatenate(rings)
    ends = np.concatenate([np.roll(r, -1, axis=0) for r in rings])
    centres = np.asarray([c["center"] for c in data["cylinders"]], float)
    radii = np.asarray([c["radius"] for c in data["cylinders"]], float)
    return World2D(starts, ends, centres, radii, rings[0])


def raycast(world: World2D, pose: np.ndarray, angles_rad: np.ndarray = ANGLES_RAD) -> np.ndarray:
    """Noise-free distance (m) from sensor pose [x, y, yaw] along each beam to the first hit, ``inf`` if none."""
    ox, oy, yaw = pose
    dx, dy = np.cos(angles_rad + yaw)[:, None], np.sin(angles_rad + yaw)[:, None]
    # Segments: o + t d = a + u e.
    ex = (world.seg_end - world.seg_start)[:, 0]
    ey = (world.seg_end - world.seg_start)[:, 1]
    wx, wy = world.seg_start[:, 0] - ox, world.seg_start[:, 1] - oy
    denom = dx * ey - dy * ex
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (wx * ey - wy * ex) / denom
        u = (wx * dy - wy * dx) / denom
    t = np.where((np.abs(denom) > 1e-12) & (t > 0) & (u >= 0) & (u <= 1), t, np.inf)
    # Circles: |o + t d - c|^2 = r^2, nearest positive root.
    cx, cy = world.circle_centres[:, 0] - ox, world.circle_centres[:, 1] - oy
    proj = dx * cx + dy * cy
    disc = proj**2 - (cx**2 + cy**2 - world.circle_radii**2)
    with np.errstate(invalid="ignore"):
        tc = proj - np.sqrt(disc)
    tc = np.where((disc >= 0) & (tc > 0), tc, np.inf)
    return np.minimum(t.min(axis=1), tc.min(axis=1))


def lds01_ranges(world: World2D, pose: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """A 360-beam LDS-01 scan (m) from sensor pose [x, y, yaw]: noisy, ``inf`` outside 0.12-3.5 m."""
    r = raycast(world, pose) + rng.normal(0.0, NOISE_SD_M, N_BEAMS)
    return np.where((r >= RANGE_MIN_M) & (r <= RANGE_MAX_M), r, np.inf)


def relative_pose(pose_ref: np.ndarray, pose_cur: np.ndarray) -> np.ndarray:
    """[x, y, theta] of world pose ``pose_cur`` in the frame of world pose ``pose_ref``."""
    c, s = np.cos(pose_ref[2]), np.sin(pose_ref[2])
    d = pose_cur[:2] - pose_ref[:2]
    dth = (pose_cur[2] - pose_ref[2] + np.pi) % (2 * np.pi) - np.pi
    return np.array([c * d[0] + s * d[1], -s * d[0] + c * d[1], dth])


def _inside(poly: np.ndarray, x: float, y: float) -> bool:
    a, b = poly, np.roll(poly, -1, axis=0)
    crosses = (a[:, 1] > y) != (b[:, 1] > y)
    with np.errstate(divide="ignore", invalid="ignore"):
        xi = a[:, 0] + (y - a[:, 1]) * (b[:, 0] - a[:, 0]) / (b[:, 1] - a[:, 1])
    return bool(np.sum(crosses & (x < xi)) % 2)


def _free(world: World2D, x: float, y: float, clearance_m: float) -> bool:
    if not _inside(world.free_polygon, x, y):
        return False
    if np.any(np.hypot(world.circle_centres[:, 0] - x, world.circle_centres[:, 1] - y) < world.circle_radii + clearance_m):
        return False
    # Distance to the wall segments.
    a, e = world.seg_start, world.seg_end - world.seg_start
    s = np.clip(((x - a[:, 0]) * e[:, 0] + (y - a[:, 1]) * e[:, 1]) / (e**2).sum(axis=1), 0, 1)
    return bool(np.hypot(a[:, 0] + s * e[:, 0] - x, a[:, 1] + s * e[:, 1] - y).min() >= clearance_m)


@dataclass(frozen=True)
class ScanPair:
    """Two LDS-01 scans from nearby poses and the true pose of the current scan in the reference scan's frame."""

    reference_ranges: np.ndarray
    current_ranges: np.ndarray
    truth: np.ndarray  # [x, y, theta], p_ref = R(theta) p_cur + [x, y]

    @property
    def angles(self) -> np.ndarray:
        return ANGLES_RAD

    @property
    def reference_points(self) -> np.ndarray:
        return _points(self.reference_ranges)

    @property
    def current_points(self) -> np.ndarray:
        return _points(self.current_ranges)


def _points(ranges: np.ndarray) -> np.ndarray:
    keep = np.isfinite(ranges)
    return np.column_stack((ranges[keep] * np.cos(ANGLES_RAD[keep]), ranges[keep] * np.sin(ANGLES_RAD[keep])))


def scan_pairs(n: int, seed: int = 0, max_step_m: float = 0.1, max_turn_rad: float = 0.1) -> list[ScanPair]:
    """``n`` scan pairs from random free poses in the TurtleBot3 world (at least 0.25 m from obstacles)."""
    world = turtlebot3_world()
    rng = np.random.default_rng(seed)
    pairs: list[ScanPair] = []
    while len(pairs) < n:
        x, y = rng.uniform(-2.8, 2.8, 2)
        yaw = rng.uniform(-np.pi, np.pi)
        step = rng.uniform(0, max_step_m)
        heading = yaw + rng.uniform(-0.5, 0.5)
        x2, y2 = x + step * np.cos(heading), y + step * np.sin(heading)
        if not (_free(world, x, y, 0.25) and _free(world, x2, y2, 0.25)):
            continue
        ref_pose = np.array([x, y, yaw])
        cur_pose = np.array([x2, y2, yaw + rng.uniform(-max_turn_rad, max_turn_rad)])
        pairs.append(ScanPair(lds01_ranges(world, ref_pose, rng), lds01_ranges(world, cur_pose, rng),
                              relative_pose(ref_pose, cur_pose)))
    return pairs
