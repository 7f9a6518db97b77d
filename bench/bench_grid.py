"""Occupancy-grid mapping throughput: 360-beam, 3.5 m scans into a 5 cm grid.

Same scans, same run, one core, against (a) a plain per-beam Bresenham loop in
Python and (b) OctoMap through its Python binding pyoctomap (``insertPointCloud``
of the scan's end points at z = 0, 5 cm voxels), when pyoctomap is installed
(``pip install pyoctomap``; benchmark only, not a bagtools dependency).
"""

from __future__ import annotations

import math

import numpy as np

from bagtools.grid import OccupancyGrid
from bench.common import Row, best_time_s

RESOLUTION = 20.0  # cells per metre: 5 cm
MAX_RANGE_M = 3.5
N_BEAMS = 360
ROOM_HALF_M = (4.0, 3.0)  # an 8 m x 6 m room: some beams reach max range
INVERSE_MODEL = (0.4, 0.7)


def make_scans(n_scans: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Poses (S, 3) inside a rectangular room, angles (N,), ranges (S, N) with 1 cm noise."""
    rng = np.random.default_rng(seed)
    half = np.array(ROOM_HALF_M)
    poses = np.column_stack([rng.uniform(-half + 0.5, half - 0.5, (n_scans, 2)), rng.uniform(-np.pi, np.pi, n_scans)])
    angles = np.linspace(0.0, 2 * np.pi, N_BEAMS, endpoint=False)
    ranges = np.empty((n_scans, N_BEAMS))
    for s, pose in enumerate(poses):
        d = np.column_stack([np.cos(angles + pose[2]), np.sin(angles + pose[2])])
        with np.errstate(divide="ignore"):
            t = np.where(d > 0, (half - pose[:2]) / d, np.where(d < 0, (-half - pose[:2]) / d, np.inf))
        ranges[s] = t.min(axis=1)
    ranges += rng.normal(0.0, 0.01, ranges.shape)
    ranges[ranges >= MAX_RANGE_M] = np.inf  # the sensor reports nothing beyond max range
    return poses, angles, ranges


def bagtools_map(poses: np.ndarray, angles: np.ndarray, ranges: np.ndarray) -> OccupancyGrid:
    grid = OccupancyGrid(2.0, 2.0, RESOLUTION, poses[0, :2] - 1.0)  # grows as the scans need
    for pose, scan in zip(poses, ranges):
        grid.insert_ray(pose, scan, angles, MAX_RANGE_M, INVERSE_MODEL)
    return grid


def bresenham_map(poses: np.ndarray, angles: np.ndarray, ranges: np.ndarray) -> np.ndarray:
    """The baseline: per scan, per beam, integer Bresenham in Python; free along, occupied at the end."""
    half = np.array(ROOM_HALF_M) + MAX_RANGE_M
    cols, rows = (2 * half * RESOLUTION).astype(int) + 2
    log_odds = np.zeros((rows, cols))
    l_free = math.log(INVERSE_MODEL[0] / (1 - INVERSE_MODEL[0]))
    l_occ = math.log(INVERSE_MODEL[1] / (1 - INVERSE_MODEL[1]))
    l_min, l_max = math.log(0.001 / 0.999), math.log(0.999 / 0.001)
    for pose, scan in zip(poses, ranges):
        x0 = int((pose[0] + half[0]) * RESOLUTION)
        y0 = int((pose[1] + half[1]) * RESOLUTION)
        for angle, r in zip(angles, scan):
            if math.isnan(r):
                continue
            hit = r < MAX_RANGE_M
            r = min(r, MAX_RANGE_M)
            x1 = int((pose[0] + r * math.cos(pose[2] + angle) + half[0]) * RESOLUTION)
            y1 = int((pose[1] + r * math.sin(pose[2] + angle) + half[1]) * RESOLUTION)
            dx, dy = abs(x1 - x0), -abs(y1 - y0)
            sx, sy = (1 if x0 < x1 else -1), (1 if y0 < y1 else -1)
            err, x, y = dx + dy, x0, y0
            while x != x1 or y != y1:
                log_odds[y, x] += l_free
                e2 = 2 * err
                if e2 >= dy:
                    err += dy
                    x += sx
                if e2 <= dx:
                    err += dx
                    y += sy
            log_odds[y, x] += l_occ if hit else l_free
        np.clip(log_odds, l_min, l_max, out=log_odds)
    return log_odds


def octomap_map(poses: np.ndarray, angles: np.ndarray, ranges: np.ndarray, pyoctomap) -> object:
    tree = pyoctomap.OcTree(1.0 / RESOLUTION)
    for pose, scan in zip(poses, ranges):
        ok = ~np.isnan(scan)
        # beyond max range: a point just past it, which OctoMap truncates to free space only
        r = np.minimum(scan[ok], MAX_RANGE_M + 0.05)
        a = angles[ok] + pose[2]
        points = np.column_stack([pose[0] + r * np.cos(a), pose[1] + r * np.sin(a), np.zeros(r.size)])
        tree.insertPointCloud(points, np.array([pose[0], pose[1], 0.0]), max_range=MAX_RANGE_M)
    return tree


def run(quick: bool) -> list[Row]:
    n_scans = 40 if quick else 200
    poses, angles, ranges = make_scans(n_scans)
    measure = f"insert {N_BEAMS}-beam {MAX_RANGE_M:g} m scans, {100 / RESOLUTION:g} cm cells"
    t_ours = best_time_s(lambda: bagtools_map(poses, angles, ranges))
    t_bres = best_time_s(lambda: bresenham_map(poses, angles, ranges), repeat=2)
    rows = [Row("grid", measure, n_scans / t_ours, "scans/s", "per-beam Bresenham loop in Python", n_scans / t_bres)]
    try:
        import pyoctomap
    except ImportError:
        rows.append(Row("grid", measure, n_scans / t_ours, "scans/s",
                        "OctoMap insertPointCloud: pyoctomap not installed (pip install pyoctomap)", float("nan"),
                        target=">= 5x OctoMap"))
    else:
        t_octo = best_time_s(lambda: octomap_map(poses, angles, ranges, pyoctomap))
        rows.append(Row("grid", measure, n_scans / t_ours, "scans/s", "OctoMap insertPointCloud (pyoctomap)",
                        n_scans / t_octo, target=">= 5x OctoMap"))
    return rows
