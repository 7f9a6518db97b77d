"""2D NDT scan matching against Open3D's ICP on the same synthetic LDS-01 scan pairs.

Each pair (bench.scan_pairs: TurtleBot3 world, 360 beams, 1 cm range noise,
poses up to 0.1 m / 0.1 rad apart) is matched from an initial guess off the
truth by 5 cm, 5 cm and 0.05 rad (random signs). A match succeeds within 2 cm
and 0.5 degrees of the truth. Times are per pair on one core: bagtools' NDT
including building the reference grids; Open3D's point-to-plane ICP including
the normal estimation it needs; Open3D's generalized ICP (its own covariance
estimation is part of the call).

Open3D works in 3D: each 2D point is lifted to two points at z = +-5 cm so
normals and covariances are not degenerate (a single plane of points leaves
GICP's covariances singular; +-1 cm was slower for GICP and no more accurate).
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np
import open3d as o3d

from bagtools.ndt import match_scans
from bench.common import Row
from bench.scan_pairs import ScanPair, scan_pairs

OFFSET = np.array([0.05, 0.05, 0.05])
SUCCESS_M = 0.02
SUCCESS_RAD = np.radians(0.5)
LIFT_Z_M = 0.05
MAX_CORRESPONDENCE_M = 0.2
ICP_ITERATIONS = 50


def _lift(points: np.ndarray) -> o3d.geometry.PointCloud:
    n = len(points)
    xyz = np.zeros((2 * n, 3))
    xyz[:n, :2] = xyz[n:, :2] = points
    xyz[:n, 2], xyz[n:, 2] = LIFT_Z_M, -LIFT_Z_M
    return o3d.geometry.PointCloud(o3d.utility.Vector3dVector(xyz))


def _matrix(pose: np.ndarray) -> np.ndarray:
    c, s = np.cos(pose[2]), np.sin(pose[2])
    m = np.eye(4)
    m[:2, :2] = [[c, -s], [s, c]]
    m[:2, 3] = pose[:2]
    return m


def _pose(matrix: np.ndarray) -> np.ndarray:
    return np.array([matrix[0, 3], matrix[1, 3], np.arctan2(matrix[1, 0], matrix[0, 0])])


def _ndt(cell_size: float, cell_model: str = "paper") -> Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]:
    def run(current: np.ndarray, reference: np.ndarray, initial: np.ndarray) -> np.ndarray:
        return match_scans(current, reference, initial_pose=initial, cell_size=cell_size, cell_model=cell_model).pose
    return run


def _criteria():
    return o3d.pipelines.registration.ICPConvergenceCriteria(1e-6, 1e-6, ICP_ITERATIONS)


def _point_to_plane(current: np.ndarray, reference: np.ndarray, initial: np.ndarray) -> np.ndarray:
    source, target = _lift(current), _lift(reference)
    target.estimate_normals(o3d.geometry.KDTreeSearchParamKNN(10))
    result = o3d.pipelines.registration.registration_icp(
        source, target, MAX_CORRESPONDENCE_M, _matrix(initial),
        o3d.pipelines.registration.TransformationEstimationPointToPlane(), _criteria())
    return _pose(result.transformation)


def _generalized(current: np.ndarray, reference: np.ndarray, initial: np.ndarray) -> np.ndarray:
    source, target = _lift(current), _lift(reference)
    result = o3d.pipelines.registration.registration_generalized_icp(
        source, target, MAX_CORRESPONDENCE_M, _matrix(initial),
        o3d.pipelines.registration.TransformationEstimationForGeneralizedICP(), _criteria())
    return _pose(result.transformation)


def evaluate(method, pairs: list[ScanPair], initials: list[np.ndarray]) -> dict[str, float]:
    """Success rate (%), median translation error (mm) and median time (ms) of ``method`` over ``pairs``."""
    errors, times = [], []
    for pair, initial in zip(pairs, initials):
        current, reference = pair.current_points, pair.reference_points
        t0 = time.perf_counter()
        pose = method(current, reference, initial)
        times.append(time.perf_counter() - t0)
        d = pose - pair.truth
        errors.append((np.hypot(d[0], d[1]), abs((d[2] + np.pi) % (2 * np.pi) - np.pi)))
    err = np.array(errors)
    success = (err[:, 0] < SUCCESS_M) & (err[:, 1] < SUCCESS_RAD)
    return {"success": 100.0 * success.mean(), "error_mm": 1000.0 * float(np.median(err[:, 0])),
            "ms": 1000.0 * float(np.median(times))}


def run(quick: bool) -> list[Row]:
    o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Error)
    pairs = scan_pairs(40 if quick else 300, seed=11)
    rng = np.random.default_rng(12)
    initials = [p.truth + OFFSET * rng.choice([-1.0, 1.0], 3) for p in pairs]
    # Warm up imports and caches so the first pair is not charged for them.
    for method in (_ndt(1.0), _point_to_plane, _generalized):
        method(pairs[0].current_points, pairs[0].reference_points, initials[0])
    gicp = evaluate(_generalized, pairs, initials)
    p2pl = evaluate(_point_to_plane, pairs, initials)
    rows: list[Row] = []
    for model, cell in (("paper", 1.0), ("paper", 0.5), ("widened", 1.0), ("widened", 0.5)):
        ndt = evaluate(_ndt(cell, model), pairs, initials)
        cap = f"NDT scan match, {model} cells of {cell:g} m"
        rows += [
            Row(cap, "success rate (2 cm, 0.5 deg)", ndt["success"], "%", "Open3D GICP", gicp["success"], True, ">= 99 %"),
            Row(cap, "median translation error", ndt["error_mm"], "mm", "Open3D GICP", gicp["error_mm"], False, "< 2 mm"),
            Row(cap, "median time per pair (incl. reference)", ndt["ms"], "ms", "Open3D GICP", gicp["ms"], False, "<= 1.5 ms"),
            Row(cap, "median time per pair (incl. reference)", ndt["ms"], "ms", "Open3D point-to-plane ICP + normals",
                p2pl["ms"], False, ""),
        ]
    rows += [
        Row("Open3D point-to-plane ICP (reference)", "success rate (2 cm, 0.5 deg)", p2pl["success"], "%", "Open3D GICP",
            gicp["success"], True, ""),
        Row("Open3D point-to-plane ICP (reference)", "median translation error", p2pl["error_mm"], "mm", "Open3D GICP",
            gicp["error_mm"], False, ""),
    ]
    return rows
