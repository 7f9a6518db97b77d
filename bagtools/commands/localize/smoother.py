"""The tracked poses smoothed offline: map matches, laser odometry and revisits in one pose graph (GTSAM).

The tracker places each scan alone against the map. Its poses carry the map
match's noise (the raster's cells, walls the map draws a little elsewhere),
which differs from one scan to the next; the laser odometry's matches of each
scan against its keyframe are far more precise over a short span, but drift.
:func:`smooth_track` joins the two, as a localizer that keeps a trajectory
would (Cartographer's pure localization optimizes its trajectory against the
frozen map):

- nodes: the scans the tracker placed, at its poses;
- between factors: the front end's matches (``T_ref_cur`` of each scan
  against its keyframe, with the matcher's covariance), Gaussian;
- prior factors: the scans matched well on the map (not carried by the
  motion), at the tracker's pose less the map matches' offset from the base
  (:func:`map_offset`), with ``MAP_SIGMA`` per ``MAP_SPAN_M`` of
  path, under a Cauchy kernel: a match the motion contradicts pulls with a
  bounded force. A map match's error is the map's error at that place, the
  same for every scan that sees it from there: a robot standing still, or
  one recording many scans per metre, gets no surer of where it is for each
  scan. So each prior weighs its share of MAP_SPAN_M since the matched scan
  before it (a turn counts ``turn_m_per_rad`` per radian, as in slam's graph
  distances); scans that far apart or more (CSAIL's, a metre apart) weigh one
  full MAP_SIGMA each. And a match weighs as well as the map explains its scan:
  its share times (its score over the median matched score, at most 1) to the
  ``MAP_SCORE_POWER``: where the map saw a place only from afar, or in part,
  its matches say less;
- revisit factors (:func:`revisit_factors`): a keyframe the map places
  within ``REVISIT_RADIUS_M`` of an older keyframe, at least slam's
  ``min_travel_m`` of path later, matched against the scans around the older
  one as slam closes a loop (:class:`~bagtools.pose_graph.constraints.LoopClosureSearch`,
  slam's defaults), in a window of ``REVISIT_GATE_SIGMAS`` x ``REVISIT_SIGMA``
  around where the map puts it, under the same kernel. The map alone places
  two visits of a place apart by its own errors, which differ with the
  direction the place is seen from (a raytraced map's walls lie a little
  behind what the laser saw, so two visits in opposite directions disagree by
  twice that); the scans themselves do not.

The graph is cut where the tracker lost the robot (a kidnap, or the scans put
it where its motion could not take it): the stretches on either side are
smoothed apart, each held by its own map matches. A stretch with no map match
keeps the tracker's poses. Levenberg-Marquardt from the tracker's poses.

Poses are [x, y, theta] of the base in the map frame; steps are the front
end's, in recording order, indexed like the tracker's scans.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable, Sequence

import gtsam
import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from bagtools.odometry.steps import ScanStep
from bagtools.progress import progress
from bagtools.pose_graph.backend import UNLINKED_COVARIANCE
from bagtools.pose_graph.constraints import LoopClosureSearch
from bagtools.pose_graph.loops import LoopOptions
from bagtools.pose_graph.graph import check_covariance
from bagtools.transforms import se2_between, se2_compose, wrap_to_pi

#: Standard deviations (m, m, rad) of a map match's pose in the graph. The matches' errors are not independent
#: from scan to scan (the map's own errors stay where they are), so they hold the trajectory against drift while
#: the laser odometry shapes it. Measured on the benchmark logs in their SLAM maps (bench/RESULTS.md).
MAP_SIGMA = (0.2, 0.2, 0.05)
#: ... per this much of path (m): map matches closer together share their weight (see the module docstring).
MAP_SPAN_M = 0.2
#: A map match weighs at least this share (1 mm of MAP_SPAN_M): a robot standing still still counts its scans a little.
MIN_MAP_SHARE = 0.005
#: ... times (its score over the median matched score, at most 1) to this power: a scan the map explains in part
#: (a place it saw from afar) places the robot less surely.
MAP_SCORE_POWER = 2.0
#: The laser odometry drifts by this much per metre of a match (m/m, rad/m), whatever its matcher's covariance
#: says: 1 to 2 % on the benchmark logs. A bag with scans far apart (CSAIL: a scan every metre or so) leans less
#: on its long steps.
ODOMETRY_DRIFT = (0.02, 0.01)
#: Cauchy kernel width on the whitened map residual (in sigmas).
MAP_KERNEL = 2.0


#: The map matches' offset from the base (:func:`map_offset`) is measured between each matched scan and the first
#: matched scan this much path later (m; a turn counting LoopOptions.turn_m_per_rad per radian): a turn round on
#: the spot (1.6 m) fits in one pair, and the laser odometry drifts a few centimetres at most over it. (Ten scans
#: on: CSAIL's scans are a metre apart, and its laser odometry's error over ten of them bends the estimate.)...
OFFSET_SPAN_M = 2.0
#: ... each pair weighed by its two matches' noise (m; the tracker's matches scatter by about this) and the laser
#: odometry's drift over its path (ODOMETRY_DRIFT); the offset is none unless the turns say otherwise, within
#: OFFSET_PRIOR_M.
OFFSET_MATCH_M, OFFSET_PRIOR_M = 0.01, 0.05


#: A keyframe whose map pose lies this close (m) to an older keyframe's, at least LoopOptions.min_travel_m of path
#: later, is a revisit: matched against the scans around the older one, as slam closes a loop.
REVISIT_RADIUS_M = 1.0
#: How well the map places two keyframes relative to each other (m, rad): the revisit's search window.
REVISIT_SIGMA = (0.1, 0.05)
#: A revisit match further than this many REVISIT_SIGMA from where the map puts it is not joined.
REVISIT_GATE_SIGMAS = 3.0


def revisit_factors(steps: Sequence[ScanStep], poses: dict[int, np.ndarray],
                    options: LoopOptions | None = None) -> list[tuple[int, int, np.ndarray, np.ndarray]]:
    """(a, b, T_a_b, covariance) of the tracked keyframes ``b`` that see the place of an older keyframe ``a``
    again (scan indexes; T_a_b [x, y, theta] of b's base in a's, m and rad), matched scans to scans (slam's loop
    match, :class:`LoopClosureSearch`: ``a`` and its neighbours against ``b`` and its predecessors, placed by the
    front end's poses) in a window around where the map ``poses`` put them: two visits of a place tied by what
    the laser saw, not by the map's raster. At most ``options.max_candidates`` older passes per keyframe."""
    options = dataclasses.replace(options or LoopOptions(), search_radius_m=REVISIT_RADIUS_M)
    keys = [i for i, s in enumerate(steps) if (s.keyframe or i == 0) and i in poses]
    if len(keys) < 2:
        return []
    front = np.array([np.asarray(steps[i].pose, dtype=np.float64) for i in keys])  # the laser odometry's: local maps
    where = np.array([np.asarray(poses[i], dtype=np.float64) for i in keys])  # the map's
    search = LoopClosureSearch(options)
    for n, i in enumerate(keys):
        motion = None if n == 0 else se2_between(front[n - 1], front[n])
        try:
            covariance = None if n == 0 else check_covariance(steps[i].covariance, f"scan {i}")
        except ValueError:
            covariance = UNLINKED_COVARIANCE
        search.add_keyframe(steps[i].points_base, motion, covariance)
    factors = []
    gate = REVISIT_GATE_SIGMAS * np.asarray(REVISIT_SIGMA)
    sure = np.zeros(len(keys))  # the map places every keyframe: no drift widens the reach
    for b in progress(range(len(keys)), total=len(keys), desc="revisits", unit="keyframe"):
        for a in search.candidates(b, where, sure, []):
            guess = se2_between(where[a], where[b])
            cand = search.match(a, b, front, REVISIT_SIGMA, guess=guess)
            if cand.T_old_new is None:
                continue
            off = se2_between(guess, cand.T_old_new)
            if np.hypot(off[0], off[1]) <= gate[0] and abs(off[2]) <= gate[1]:
                factors.append((keys[a], keys[b], np.asarray(cand.T_old_new, dtype=np.float64), cand.covariance))
    return factors


def map_offset(steps: Sequence[ScanStep], poses: dict[int, np.ndarray], matched: Iterable[int],
               cuts: Iterable[int] = ()) -> np.ndarray:
    """Where the map matches put the base, relative to where it is: the offset ``o`` (2,) (m, base frame: x ahead,
    y to the left) of ``Z = X o`` (the match Z, the base X, o a pure translation), the same at every scan.

    A map raytraced from scans draws a wall a little behind where the laser saw it, and NDT's cells blur its
    corners: with a laser that looks ahead, every match places the base a little ahead (8-24 mm on the benchmark
    logs' slam maps). Two visits of a place in opposite directions are then put twice that apart. The offset shows
    where the robot turns: between two matched scans i and j, the front end's motion (t, phi) is the base's, and
    the matches' motion is t + (R(phi) - I) o (a lever arm, as hand-eye calibration finds one). Weighted least
    squares over each matched scan of ``poses`` and the first matched scan OFFSET_SPAN_M of path later (no cut
    between), each pair weighed by OFFSET_MATCH_M for each match and the laser odometry's drift (ODOMETRY_DRIFT)
    over its path, under a Cauchy kernel (MAP_KERNEL); with none as the prior, within OFFSET_PRIOR_M: a robot that
    never turns leaves it at zero. Zeros without pairs."""
    keys = np.array(sorted(k for k in matched if k in poses), dtype=np.int64)
    front = np.array([steps[k].pose for k in keys], dtype=np.float64).reshape(-1, 3)
    travelled = np.r_[0.0, np.cumsum(_path_m(front))]
    later = np.searchsorted(travelled, travelled + OFFSET_SPAN_M)  # the first matched scan that far on
    first = np.flatnonzero(later < len(keys))
    then = later[first]
    cut_at = np.sort(np.fromiter(cuts, dtype=np.int64))
    joined = np.searchsorted(cut_at, keys[first], side="right") == np.searchsorted(cut_at, keys[then], side="right")
    first, then = first[joined], then[joined]
    if first.size == 0:
        return np.zeros(2)
    placed = np.array([poses[k] for k in keys], dtype=np.float64)
    seen = se2_between(placed[first], placed[then])
    moved = se2_between(front[first], front[then])
    c, s = np.cos(moved[:, 2]), np.sin(moved[:, 2])
    lever = np.stack([np.stack([c - 1.0, -s], axis=1), np.stack([s, c - 1.0], axis=1)], axis=1)  # R(phi) - I
    sd = np.sqrt(2.0 * OFFSET_MATCH_M**2 + (ODOMETRY_DRIFT[0] * np.hypot(moved[:, 0], moved[:, 1])) ** 2)
    A, y = lever / sd[:, None, None], (seen[:, :2] - moved[:, :2]) / sd[:, None]
    weight, offset = np.ones(len(y)), np.zeros(2)
    for _ in range(10):  # iteratively reweighted: a wrong match weighs as the kernel says
        normal = np.einsum("n,nki,nkj->ij", weight, A, A) + np.eye(2) / OFFSET_PRIOR_M**2
        offset = np.linalg.solve(normal, np.einsum("n,nki,nk->i", weight, A, y))
        r = y - np.einsum("nij,j->ni", A, offset)
        weight = 1.0 / (1.0 + np.einsum("ni,ni->n", r, r) / MAP_KERNEL**2)
    return offset


def smooth_track(steps: Sequence[ScanStep], poses: dict[int, np.ndarray], matched: Iterable[int],
                 cuts: Iterable[int] = (), revisits: Sequence[tuple[int, int, np.ndarray, np.ndarray]] = (),
                 offset: np.ndarray | None = None, scores: dict[int, float] | None = None) -> dict[int, np.ndarray]:
    """Smoothed map poses of the tracked scans (see the module docstring).

    Args:
        steps: the front end's steps, one per scan, in recording order.
        poses: scan index -> [x, y, theta] of the base in the map (the tracker's).
        matched: the scans of ``poses`` placed by a good map match (prior factors).
        cuts: scan indexes where the robot was lost: no odometry factor joins a scan before one to a scan at or
            after it.
        revisits: (a, b, T_a_b, covariance) between tracked scans (:func:`revisit_factors`), across cuts too
            (both ends are placed in the map).
        offset: the map matches' offset from the base (:func:`map_offset`; None: none): the prior factors hold
            the base where the match is less it.
        scores: scan index -> the tracker's score of its map match (None: every match weighs alike).
    Returns:
        scan index -> smoothed [x, y, theta], for every scan of ``poses``.
    """
    nodes = sorted(poses)
    if not nodes:
        return {}
    cut_at = np.sort(np.fromiter(cuts, dtype=np.int64))
    matched = {k for k in matched if k in poses}
    between = _between_factors(steps, poses, cut_at)
    number = {k: n for n, k in enumerate(nodes)}
    # Each stretch joined by the odometry must hold a map match, or its poses stay the tracker's.
    rows = [number[i] for i, _, _, _ in between]
    cols = [number[j] for _, j, _, _ in between]
    _, label = connected_components(coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(len(nodes),) * 2),
                                    directed=False)
    anchored = {label[number[k]] for k in matched}
    keep = {k for k in nodes if label[number[k]] in anchored}

    graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
    for k in keep:
        values.insert(k, gtsam.Pose2(*poses[k]))
    for i, j, T, covariance in between:
        if i in keep:
            graph.add(gtsam.BetweenFactorPose2(i, j, gtsam.Pose2(*T), gtsam.noiseModel.Gaussian.Covariance(covariance)))
    kernel = gtsam.noiseModel.mEstimator.Cauchy.Create(MAP_KERNEL)
    for i, j, T, covariance in revisits:
        if i in keep and j in keep:
            revisit = gtsam.noiseModel.Robust.Create(kernel, gtsam.noiseModel.Gaussian.Covariance(covariance))
            graph.add(gtsam.BetweenFactorPose2(i, j, gtsam.Pose2(*T), revisit))
    back = np.zeros(3) if offset is None else np.r_[-np.asarray(offset, dtype=np.float64), 0.0]
    for k, share in _map_shares(steps, matched, scores).items():
        noise = gtsam.noiseModel.Diagonal.Sigmas(np.asarray(MAP_SIGMA) / np.sqrt(share))
        graph.add(gtsam.PriorFactorPose2(k, gtsam.Pose2(*se2_compose(poses[k], back)),
                                         gtsam.noiseModel.Robust.Create(kernel, noise)))
    smoothed = {k: np.asarray(poses[k], dtype=np.float64).copy() for k in nodes}
    if keep:
        params = gtsam.LevenbergMarquardtParams()
        params.setMaxIterations(100)
        result = gtsam.LevenbergMarquardtOptimizer(graph, values, params).optimize()
        for k in keep:
            p = result.atPose2(k)
            smoothed[k] = np.array([p.x(), p.y(), p.theta()])
    return smoothed


def _map_shares(steps: Sequence[ScanStep], matched: Iterable[int],
                scores: dict[int, float] | None = None) -> dict[int, float]:
    """Matched scan -> the share of MAP_SPAN_M (in (0, 1]) of path since the matched scan before it (the first:
    1), measured on the front end's poses, a turn counting LoopOptions.turn_m_per_rad per radian; times (its
    score over the median of ``scores``, at most 1) to the MAP_SCORE_POWER (a scan without a score: 1)."""
    keys = np.array(sorted(matched), dtype=np.int64)
    if keys.size == 0:
        return {}
    pose = np.array([np.asarray(steps[k].pose, dtype=np.float64) for k in keys]).reshape(-1, 3)
    share = np.r_[1.0, np.clip(_path_m(pose) / MAP_SPAN_M, MIN_MAP_SHARE, 1.0)]
    if scores:
        score = np.array([scores.get(k, np.inf) for k in keys.tolist()], dtype=np.float64)
        known = score[np.isfinite(score)]
        if known.size:
            share *= np.minimum(score / max(float(np.median(known)), 1e-12), 1.0) ** MAP_SCORE_POWER
    return dict(zip(keys.tolist(), share.tolist()))


def _path_m(poses: np.ndarray) -> np.ndarray:
    """(N - 1,) path (m) between consecutive poses (N, 3) [x, y, theta], a turn counting
    LoopOptions.turn_m_per_rad per radian (as slam's graph distances)."""
    step = np.diff(poses, axis=0)
    return np.hypot(step[:, 0], step[:, 1]) + LoopOptions().turn_m_per_rad * np.abs(wrap_to_pi(step[:, 2]))


def _between_factors(steps: Sequence[ScanStep], poses: dict[int, np.ndarray],
                     cut_at: np.ndarray) -> list[tuple[int, int, np.ndarray, np.ndarray]]:
    """(i, j, T_i_j, covariance) of the front end's matches between tracked scans not split by a cut: each scan's
    match against its keyframe; when that keyframe is not tracked or a cut lies between, the front end's motion
    from the scan before, with the same covariance."""
    factors = []
    for j in sorted(poses):
        if j == 0 or j >= len(steps):
            continue
        s = steps[j]
        ref = int(s.reference)
        if ref >= 0 and ref in poses and not _split(cut_at, ref, j):
            T = np.asarray(s.T_ref_cur, dtype=np.float64)
        elif j - 1 in poses and not _split(cut_at, j - 1, j):
            ref, T = j - 1, se2_between(steps[j - 1].pose, s.pose)
        else:
            continue
        try:
            covariance = check_covariance(s.covariance, f"scan {j}")
        except ValueError:
            continue  # a match the front end could not say the uncertainty of joins nothing
        length = float(np.hypot(T[0], T[1]))
        drift = np.diag([ODOMETRY_DRIFT[0] * length, ODOMETRY_DRIFT[0] * length, ODOMETRY_DRIFT[1] * length]) ** 2
        factors.append((ref, j, T, covariance + drift))
    return factors


def _split(cut_at: np.ndarray, i: int, j: int) -> bool:
    """Does a cut lie in (i, j]?"""
    n = np.searchsorted(cut_at, i, side="right")
    return n < len(cut_at) and cut_at[n] <= j
