"""A contested front-end step: which of several places a scan was matched to wins, and the one that came second.

Candidates in distinct places (outside NDT's basin of each other) whose objectives (normalized score less the
motion prior's cost, :meth:`~bagtools.odometry.prior.MotionPrior.objective`) come within a margin of the best are
decided on a finer grid: coarse NDT cells blur what tells a sharp turn, a half-seen room or a corridor's doors from
a look-alike; a fine likelihood field does not. Poses are planar [x, y, theta] (m, m, rad) in the keyframe's frame.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from bagtools.odometry.options import AMBIGUOUS_MARGIN, BASIN_M, BASIN_RAD
from bagtools.odometry.prior import Match, MotionPrior
from bagtools.transforms.planar import se2_between_fast as _between


def close_poses(a: np.ndarray, b: np.ndarray, tol_m: float, tol_rad: float) -> bool:
    """Are poses ``a`` and ``b`` within ``tol_m`` and ``tol_rad`` of each other?"""
    d = _between(a, b)
    return bool(np.hypot(d[0], d[1]) <= tol_m and abs(d[2]) <= tol_rad)


def decide(matches: list[Match], best: Match, prior: MotionPrior, margin: float,
           fine_score: Callable[[np.ndarray], float]) -> tuple[Match, bool, Match | None]:
    """(the winner, whether the step is ambiguous, the contender that came second or None).

    ``best`` wins unless a match in another place is within ``margin`` of its objective; then each contender's
    ``fine_score`` (in [0, 1], at its pose) less its cost under the robot's reach (the prior's wide part: the
    prior's preference shortlisted them) decides, when it tells them apart by AMBIGUOUS_MARGIN; when it does not
    either, ``best`` stays and the step is ambiguous.
    """
    rivals = [m for m in matches if not close_poses(m.pose, best.pose, BASIN_M, BASIN_RAD)]
    if not rivals:
        return best, False, None
    runner_up = max(prior.objective(m) for m in rivals)
    if prior.objective(best) - runner_up >= margin:
        return best, False, None
    contenders = [best]
    for m in sorted(rivals, key=prior.objective, reverse=True):
        if prior.objective(best) - prior.objective(m) < margin and \
                not any(close_poses(m.pose, c.pose, BASIN_M, BASIN_RAD) for c in contenders):
            contenders.append(m)
    reach = prior.wide or prior  # what the robot can have done; the prior's preference shortlisted them
    fine = [fine_score(m.pose) - reach.weight * reach.cost(m.pose) for m in contenders]
    order = np.argsort(fine)[::-1]
    second = contenders[order[1]]
    if fine[order[0]] - fine[order[1]] < AMBIGUOUS_MARGIN:  # the finer grid cannot tell them apart either
        return best, True, (second if second is not best else contenders[order[0]])
    winner = contenders[order[0]]
    if winner is best:
        return best, False, second
    # the whole scan's fine field vouches for it, where its voxel-filtered score may not (far returns on new walls)
    return Match(winner.pose, max(winner.score, fine[order[0]]), winner.covariance, winner.source), False, second


__all__ = ["close_poses", "decide"]
