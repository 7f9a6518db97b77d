"""The motion prior of a front-end step and the match it weighs: prior and evidence in one objective.

A candidate pose of a scan (a :class:`Match`: pose, normalized NDT score, covariance) is judged by
:meth:`MotionPrior.objective`: its score less the prior's weighted cost, -2 log of the prior's density (squared
Mahalanobis distance from the predicted pose; a mixture with a wide "what the robot can have done" component
that pays :data:`OUTLIER_COST` for its rarity; a wheeled robot's arc; the robot's reach). :func:`ndt_covariance`
turns a match's NDT Hessian and its prior's information into the step's covariance.

Poses are planar [x, y, theta] (m, m, rad) in the keyframe's base frame.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from bagtools.odometry.motion import PRIOR_WEIGHT_DEFAULT
from bagtools.scan_matching.covariance import COVARIANCE_FLOOR, information_inverse
# single poses, tens of calls per scan: without numpy's per-call overhead on 3-vectors
from bagtools.transforms.planar import se2_between_fast as _between

#: What overruling the odometry costs, in normalized score (see MotionPrior).
OUTLIER_COST = 0.25
#: Without odometry: what overruling constant velocity's narrow spread (motion.CV_STEADY_*) costs.
CV_OUTLIER_COST = 0.12
#: A result farther than this (squared Mahalanobis, 3 sigma in 3 dof ~ 14) from the prior is searched for.
PRIOR_GATE2 = 14.0
#: A wheeled robot's step runs along an arc: its sideways offset from the chord has this spread (m, share of the step).
LATERAL_SD_M, LATERAL_SD_RATIO = 0.05, 0.1
#: Beyond what the robot can do in a step (max speed and turn rate x time), the prior's cost grows by one per
#: this much more (m, rad).
REACH_SD_M, REACH_SD_RAD = 0.05, 0.05


def ndt_covariance(hessian: np.ndarray, prior_information: np.ndarray | None = None) -> np.ndarray:
    """Covariance (3,3) of an NDT match from the Hessian of its cost and the information of its prior.

    The Hessian's negative eigenvalues (a match that ends on a ridge of the
    score in some direction) are taken as no information there, not as
    negative information, so the prior still bounds that direction. The
    inverse is taken on the positive eigenvalues of the sum (a direction
    neither constrains gets a large variance), plus :data:`COVARIANCE_FLOOR`.
    """
    values, vectors = np.linalg.eigh(0.5 * (hessian + hessian.T))
    information = (vectors * np.maximum(values, 0.0)) @ vectors.T
    if prior_information is not None:
        information = information + prior_information
    return information_inverse(information) + COVARIANCE_FLOOR


@dataclass
class Match:
    pose: np.ndarray  # in the keyframe's base frame
    score: float
    covariance: np.ndarray
    source: str


@dataclass(frozen=True)
class MotionPrior:
    """The expected pose in the keyframe frame (3,) and its standard deviations (3,) (m, m, rad).

    With ``wide`` (another prior: what the robot can have done), the prior is a
    mixture: usually ``mean``/``sd``, rarely anything ``wide`` allows (wheel
    odometry that slipped, or a corrupt sample). A candidate's cost is then the
    cheaper of the two explanations, the wide one paying OUTLIER_COST (in
    normalized score) for its rarity: the scans must be that much better
    aligned to overrule the odometry.

    With ``origin`` (the previous scan's pose, same frame), a wheeled robot's
    motion model adds its cost: a step from ``origin`` runs along an arc, so
    its sideways offset from the chord at half its turn is unlikely (see
    LATERAL_SD_M). Odometry's steps follow an arc already and have no origin.

    With ``reach`` (the previous scan's pose, the farthest the robot can move
    and turn since it: max speed and turn rate times the time step), a step
    beyond it costs steeply (REACH_SD_M, REACH_SD_RAD per unit): a scene that
    repeats a few metres away must not pull the robot faster than it can go.
    """

    mean: np.ndarray
    sd: np.ndarray
    weight: float = PRIOR_WEIGHT_DEFAULT
    wide: MotionPrior | None = None
    outlier_cost: float = 0.0
    kind: str = "kinematic"
    origin: np.ndarray | None = None
    reach: tuple[np.ndarray, float, float] | None = None

    def mahalanobis2(self, pose: np.ndarray) -> float:
        d = _between(self.mean, pose)
        cost = float((d[0] / self.sd[0]) ** 2 + (d[1] / self.sd[1]) ** 2 + (d[2] / self.sd[2]) ** 2)
        if self.origin is not None:
            step = _between(self.origin, pose)
            half = 0.5 * step[2]
            sideways = step[1] * math.cos(half) - step[0] * math.sin(half)
            sd = LATERAL_SD_M + LATERAL_SD_RATIO * math.hypot(step[0], step[1])
            cost += (sideways / sd) ** 2
        if self.reach is not None:
            start, max_m, max_rad = self.reach
            step = _between(start, pose)
            cost += (max(math.hypot(step[0], step[1]) - max_m, 0.0) / REACH_SD_M) ** 2
            cost += (max(abs(step[2]) - max_rad, 0.0) / REACH_SD_RAD) ** 2
        return cost

    def cost(self, pose: np.ndarray) -> float:
        """-2 log of the prior density relative to its peak (squared Mahalanobis for one Gaussian)."""
        narrow = self.mahalanobis2(pose)
        if self.wide is None:
            return narrow
        return min(narrow, self.wide.cost(pose) + self.outlier_cost / self.weight)

    def objective(self, match: Match) -> float:
        return match.score - self.weight * self.cost(match.pose)

    def component(self, pose: np.ndarray) -> MotionPrior:
        """The Gaussian that explains ``pose`` (the narrow one, or the wide one when that is cheaper)."""
        if self.wide is None or self.cost(pose) >= self.mahalanobis2(pose):
            return self
        return self.wide.component(pose)

    def information(self, n_points: int) -> np.ndarray:
        """This Gaussian as information on the raw NDT score of ``n_points`` points (see :func:`match_scans`)."""
        return 8.0 * n_points * self.weight * np.diag(1.0 / self.sd**2)



__all__ = ["CV_OUTLIER_COST", "LATERAL_SD_M", "LATERAL_SD_RATIO", "OUTLIER_COST", "PRIOR_GATE2",
           "REACH_SD_M", "REACH_SD_RAD", "Match", "MotionPrior", "ndt_covariance"]
