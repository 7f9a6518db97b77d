"""The back end: a pose graph of keyframes, optimized with GTSAM.

The graph is written the way GTSAM's Pose2SLAMExample reads: a
``NonlinearFactorGraph`` with a ``PriorFactorPose2`` on the first keyframe and
one ``BetweenFactorPose2`` per constraint, initial ``Values`` from the current
estimate, Levenberg-Marquardt, and the estimate read back. Nodes are keyframes
(numbered 0, 1, ... in scan order); a constraint ``T_i_j`` is the measured pose
[x, y, theta] (m, m, rad) of keyframe j's base in keyframe i's base frame, with
its 3x3 covariance (m^2, m rad, rad^2) from the matcher.

Odometry constraints (the front end's keyframe chain) have Gaussian noise;
loop constraints have a robust noise model (``noiseModel.Robust`` with a Huber
or Cauchy M-estimator on the whitened residual), so a wrong loop that got in
pulls with a bounded force. :meth:`PoseGraph.loop_chi2` gives each loop's
squared Mahalanobis residual at the estimate (Gaussian, without the kernel):
the caller drops the outliers and optimizes again.

:meth:`PoseGraph.g2o_text` is the graph in g2o's text format (VERTEX_SE2,
EDGE_SE2 with the upper triangle of the information matrix, ``FIX 0``) at full
precision, read back by ``gtsam.readG2o`` and g2o.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import gtsam
import numpy as np


ODOMETRY = "odometry"
LOOP = "loop"
KERNELS = ("huber", "cauchy", "none")


@dataclass(frozen=True)
class Constraint:
    """A measured relative pose between two keyframes.

    Attributes:
        i, j: node numbers (keyframes in scan order).
        T_i_j: (3,) [x, y, theta] of node j's base in node i's base frame (m, m, rad).
        covariance: (3,3) covariance of ``T_i_j`` (m^2, m rad, rad^2), symmetric positive definite.
        kind: ``ODOMETRY`` (the front end's chain) or ``LOOP``.
    """

    i: int
    j: int
    T_i_j: np.ndarray
    covariance: np.ndarray
    kind: str


@dataclass(frozen=True)
class Optimization:
    """One Levenberg-Marquardt run: iterations, the graph error (0.5 sum of squared whitened residuals,
    robust kernels applied) before and after, and the wall time in seconds."""

    iterations: int
    initial_error: float
    final_error: float
    time_s: float


def check_covariance(covariance: np.ndarray, what: str) -> np.ndarray:
    """``covariance`` as a symmetric (3,3) float array; ValueError unless finite and positive definite."""
    cov = np.asarray(covariance, dtype=np.float64)
    if cov.shape != (3, 3) or not np.isfinite(cov).all():
        raise ValueError(f"{what}: covariance must be a finite 3x3 matrix, got {cov!r}")
    cov = 0.5 * (cov + cov.T)
    if np.linalg.eigvalsh(cov)[0] <= 0:
        raise ValueError(f"{what}: covariance is not positive definite: {cov.tolist()}")
    return cov


@dataclass
class PoseGraph:
    """Keyframe poses (the estimate) and the constraints between them.

    Args:
        first_pose: (3,) [x, y, theta] of node 0 in the map frame; the prior holds it there.
        prior_covariance: (3,3) covariance of that prior (small: it fixes the gauge).
        loop_kernel: M-estimator of loop constraints: "huber", "cauchy" or "none" (Gaussian).
        kernel_width: the M-estimator's threshold on the whitened residual (in sigmas).
    """

    first_pose: np.ndarray
    prior_covariance: np.ndarray = field(default_factory=lambda: np.diag([1e-6, 1e-6, 1e-8]))
    loop_kernel: str = "huber"
    kernel_width: float = 3.0
    max_iterations: int = 100
    poses: np.ndarray = field(init=False)
    constraints: list[Constraint] = field(init=False, default_factory=list)

    def __post_init__(self) -> None:
        if self.loop_kernel not in KERNELS:
            raise ValueError(f"loop_kernel must be one of {', '.join(KERNELS)}, got {self.loop_kernel!r}")
        if not (math.isfinite(self.kernel_width) and self.kernel_width > 0):
            raise ValueError(f"kernel_width must be positive, got {self.kernel_width}")
        first = np.asarray(self.first_pose, dtype=np.float64).reshape(3)
        if not np.isfinite(first).all():
            raise ValueError(f"first_pose must be finite, got {first.tolist()}")
        self.first_pose = first
        self.prior_covariance = check_covariance(self.prior_covariance, "prior")
        self.poses = first[None, :].copy()

    # -- building ------------------------------------------------------------------------------

    @property
    def n_nodes(self) -> int:
        return len(self.poses)

    def add_node(self, pose: np.ndarray) -> int:
        """Append a node with the initial estimate ``pose`` (3,) in the map frame; returns its number."""
        pose = np.asarray(pose, dtype=np.float64).reshape(1, 3)
        if not np.isfinite(pose).all():
            raise ValueError(f"node pose must be finite, got {pose.tolist()}")
        self.poses = np.vstack((self.poses, pose))
        return self.n_nodes - 1

    def add(self, constraint: Constraint) -> int:
        """Add a constraint between existing nodes; returns its index in :attr:`constraints`."""
        if not (0 <= constraint.i < self.n_nodes and 0 <= constraint.j < self.n_nodes) or constraint.i == constraint.j:
            raise ValueError(f"constraint between nodes {constraint.i} and {constraint.j} of {self.n_nodes}")
        if constraint.kind not in (ODOMETRY, LOOP):
            raise ValueError(f"constraint kind must be {ODOMETRY} or {LOOP}, got {constraint.kind!r}")
        T = np.asarray(constraint.T_i_j, dtype=np.float64).reshape(3)
        if not np.isfinite(T).all():
            raise ValueError(f"constraint {constraint.i} -> {constraint.j}: T_i_j must be finite, got {T.tolist()}")
        cov = check_covariance(constraint.covariance, f"constraint {constraint.i} -> {constraint.j}")
        self.constraints.append(Constraint(constraint.i, constraint.j, T, cov, constraint.kind))
        return len(self.constraints) - 1

    def remove(self, indexes: list[int]) -> list[Constraint]:
        """Remove the constraints at ``indexes``; returns them."""
        drop = set(indexes)
        removed = [c for k, c in enumerate(self.constraints) if k in drop]
        self.constraints = [c for k, c in enumerate(self.constraints) if k not in drop]
        return removed

    def loop_indexes(self) -> list[int]:
        return [k for k, c in enumerate(self.constraints) if c.kind == LOOP]

    # -- GTSAM ---------------------------------------------------------------------------------

    def _noise(self, c: Constraint, robust: bool) -> gtsam.noiseModel.Base:
        gaussian = gtsam.noiseModel.Gaussian.Covariance(c.covariance)
        if not robust or c.kind != LOOP or self.loop_kernel == "none":
            return gaussian
        if self.loop_kernel == "huber":
            estimator = gtsam.noiseModel.mEstimator.Huber.Create(self.kernel_width)
        else:
            estimator = gtsam.noiseModel.mEstimator.Cauchy.Create(self.kernel_width)
        return gtsam.noiseModel.Robust.Create(estimator, gaussian)

    def factor_graph(self, robust: bool = True, prior: bool = True) -> gtsam.NonlinearFactorGraph:
        """The GTSAM factor graph (robust loop noise models unless ``robust`` is False)."""
        graph = gtsam.NonlinearFactorGraph()
        if prior:
            graph.add(gtsam.PriorFactorPose2(0, gtsam.Pose2(*self.first_pose),
                                             gtsam.noiseModel.Gaussian.Covariance(self.prior_covariance)))
        for c in self.constraints:
            graph.add(gtsam.BetweenFactorPose2(c.i, c.j, gtsam.Pose2(*c.T_i_j), self._noise(c, robust)))
        return graph

    def values(self) -> gtsam.Values:
        """The current estimate as GTSAM Values (keys = node numbers)."""
        values = gtsam.Values()
        for k, pose in enumerate(self.poses):
            values.insert(k, gtsam.Pose2(*pose))
        return values

    def optimize(self) -> Optimization:
        """Levenberg-Marquardt from the current estimate; the estimate becomes the optimum."""
        t0 = time.perf_counter()
        graph = self.factor_graph()
        initial = self.values()
        params = gtsam.LevenbergMarquardtParams()
        params.setMaxIterations(self.max_iterations)
        params.setRelativeErrorTol(1e-6)
        params.setAbsoluteErrorTol(1e-9)
        optimizer = gtsam.LevenbergMarquardtOptimizer(graph, initial, params)
        result = optimizer.optimize()
        poses = np.array([[p.x(), p.y(), p.theta()] for p in (result.atPose2(k) for k in range(self.n_nodes))])
        self.poses = poses
        return Optimization(int(optimizer.iterations()), float(graph.error(initial)), float(graph.error(result)),
                            time.perf_counter() - t0)

    def judge(self, extra: list[Constraint], max_chi2: float) -> np.ndarray:
        """Which of ``extra`` (constraints not in the graph) are inliers (bool, (len(extra),)) of the graph with
        them, every constraint of the graph a known inlier: GTSAM's graduated non-convexity (``GncLMOptimizer``,
        truncated least squares), a constraint being an inlier when its squared Mahalanobis residual at the
        solution is under ``max_chi2``. The estimate is not changed."""
        if not extra:
            return np.zeros(0, dtype=bool)
        graph = self.factor_graph(robust=False)
        known = graph.size()
        for c in extra:
            graph.add(gtsam.BetweenFactorPose2(c.i, c.j, gtsam.Pose2(*c.T_i_j),
                                               gtsam.noiseModel.Gaussian.Covariance(c.covariance)))
        params = gtsam.GncLMParams()
        params.setLossType(gtsam.GncLossType.TLS)
        params.setKnownInliers(list(range(known)))
        optimizer = gtsam.GncLMOptimizer(graph, self.values(), params)
        optimizer.setInlierCostThresholds(0.5 * max_chi2)  # a factor's cost is half its squared residual
        optimizer.optimize()
        return np.asarray(optimizer.getWeights())[known:] > 0.5

    def chi2(self, indexes: list[int]) -> np.ndarray:
        """Squared Mahalanobis residual (Gaussian, no kernel) of the constraints at ``indexes``, at the estimate."""
        out = np.empty(len(indexes))
        for n, k in enumerate(indexes):
            c = self.constraints[k]
            predicted = gtsam.Pose2(*self.poses[c.i]).between(gtsam.Pose2(*self.poses[c.j]))
            residual = gtsam.Pose2.Logmap(gtsam.Pose2(*c.T_i_j).between(predicted))
            out[n] = float(residual @ np.linalg.solve(c.covariance, residual))
        return out

    def loop_chi2(self) -> tuple[list[int], np.ndarray]:
        """(indexes of the loop constraints, their squared Mahalanobis residuals at the estimate)."""
        loops = self.loop_indexes()
        return loops, self.chi2(loops)

    def error(self) -> float:
        """The graph error at the estimate (0.5 sum of squared whitened residuals, robust kernels applied)."""
        return float(self.factor_graph().error(self.values()))

    def g2o_text(self) -> str:
        """The graph (every constraint, Gaussian noise; the prior is not written) and the estimate in g2o format,
        at full double precision (gtsam.writeG2o keeps 6 digits: a millimetre at 500 m), the first vertex fixed
        (``FIX 0``) as g2o expects."""
        lines = [f"VERTEX_SE2 {k} {x:.17g} {y:.17g} {theta:.17g}" for k, (x, y, theta) in enumerate(self.poses)]
        for c in self.constraints:
            info = np.linalg.inv(c.covariance)
            info = 0.5 * (info + info.T)
            upper = (info[0, 0], info[0, 1], info[0, 2], info[1, 1], info[1, 2], info[2, 2])
            lines.append(f"EDGE_SE2 {c.i} {c.j} " + " ".join(f"{v:.17g}" for v in (*c.T_i_j, *upper)))
        lines.append("FIX 0")
        return "\n".join(lines) + "\n"

