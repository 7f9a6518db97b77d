"""From the front end's keyframes to an optimized pose graph: odometry edges, loop search, GTSAM.

:func:`build_pose_graph` walks the keyframes in scan order, as an online
system would:

1. the keyframe becomes a node, placed by its odometry edge (the front end's
   ``T_ref_cur`` and ``covariance`` against the keyframe before it) on the
   current estimate of that one;
2. :class:`~bagtools.pose_graph.constraints.LoopClosureSearch` proposes older
   keyframes within reach, matches them, and
   :class:`~bagtools.pose_graph.consistency.ConsistencyCheck` accepts or rejects the
   matches; accepted ones become loop edges;
3. the graph is optimized (GTSAM Levenberg-Marquardt) when a loop corrects the
   estimate by more than ``correction_m``/``correction_rad``, or
   ``optimize_every`` keyframes after a smaller one; afterwards each loop's
   squared Mahalanobis residual is checked against ``outlier_chi2`` (scaled by
   the loops' median residual, see :meth:`_Builder.outlier_gate`), and the
   worst loop above it that no other accepted loop supports is dropped and the
   graph optimized again, until none is. A loop is supported when another,
   from scans it does not share, closes a consistent cycle with it through the
   two short chains between them: two such matches are evidence against the
   long odometry chain, whose systematic drift (a heading bias, a scale error)
   its covariances do not know, so that a loop correcting that drift has a
   large residual for the chain's fault, not its own.
   Later searches use the corrected estimate.
4. when no loop has been accepted for a while, a global search (see
   :mod:`bagtools.pose_graph.constraints`) matches the keyframe against old maps
   anywhere; its best match is followed up at the next keyframes in small
   windows around where it puts them, and enters the graph only with a
   consistent follow-up. The graph's robust loop kernel and the outlier check
   hold against a wrong pair that got through.

At the end no keyframe comes after the matches still waiting for a follow-up:
each is followed up at the keyframes before it instead (the same evidence: the
old chain, the match, and the new chain between the two keyframes). The
matches no second one confirmed are then handed to the graph (but look-alikes
and follow-ups, which repeat their match's error): GTSAM's graduated
non-convexity (``GncLMOptimizer``, truncated least squares) over the graph
with them, its constraints known inliers, takes those whose residual stays
under the outlier gate (:data:`TAKEN_BY_GRAPH` counts them); the others are
rejected, and the graph is optimized once more (with the same outlier check).

Graph distances (for the search's uncertainty) are shortest paths through the
graph (``scipy.sparse.csgraph.dijkstra``): an odometry edge weighs its length
plus ``turn_m_per_rad`` per radian turned (plus, for a loose edge the front
end is unsure of, the path over which the drift model reaches its
uncertainty), a loop edge ``loop_edge_m``.
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass, field

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

from bagtools.odometry.steps import ScanStep
from bagtools.progress import progress
from bagtools.pose_graph.consistency import ConsistencyCheck
from bagtools.pose_graph.constraints import LoopClosureSearch
from bagtools.pose_graph.loops import LoopCandidate, LoopKind, LoopOptions, LoopOutcome
from bagtools.pose_graph.graph import LOOP, ODOMETRY, Constraint, Optimization, PoseGraph, check_covariance
from bagtools.transforms import se2_between, se2_compose, wrap_to_pi

#: Covariance of the motion between two keyframes the front end did not link (m^2, m^2, rad^2): unknown.
UNLINKED_COVARIANCE = np.diag([1.0, 1.0, 0.3])
#: An odometry edge whose standard deviation exceeds these (m, rad) is loose (an ambiguous step, an unlinked
#: keyframe): in graph distance it weighs the path over which the drift model reaches that uncertainty.
LOOSE_EDGE_M, LOOSE_EDGE_RAD = 0.1, 0.1
#: chi2 of 3 degrees of freedom at 99.9 %, and its median.
CHI2_3DOF_999 = 16.27
CHI2_3DOF_MEDIAN = 2.366
#: ``BackEndResult.counts`` key (summary.json ``graph``): unconfirmed matches the graph's GNC took as inliers.
TAKEN_BY_GRAPH = "unconfirmed matches the graph took"


@dataclass(frozen=True)
class BackEndOptions:
    """Settings of :func:`build_pose_graph`; ``loop`` those of the loop search (None: no loop closure)."""

    loop: LoopOptions | None = field(default_factory=LoopOptions)
    loop_kernel: str = "huber"
    kernel_width: float = 3.0
    outlier_chi2: float = CHI2_3DOF_999
    correction_m: float = 0.05
    correction_rad: float = 0.02
    optimize_every: int = 10
    max_outlier_rounds: int = 20
    min_loops_for_scale: int = 10

    def __post_init__(self) -> None:
        if not (math.isfinite(self.outlier_chi2) and self.outlier_chi2 > 0):
            raise ValueError(f"outlier_chi2 must be positive, got {self.outlier_chi2!r}")
        if self.optimize_every < 1 or self.max_outlier_rounds < 0:
            raise ValueError("optimize_every must be at least 1 and max_outlier_rounds not negative")


@dataclass
class BackEndResult:
    """The optimized graph and how it was built.

    ``keyframe_steps`` (K,): the step index of each node; ``candidates``: every
    loop candidate in the order searched; ``optimizations``: every GTSAM run;
    ``counts``: events by kind; ``warnings``: one line each.
    """

    graph: PoseGraph
    keyframe_steps: np.ndarray
    candidates: list[LoopCandidate]
    optimizations: list[Optimization]
    counts: Counter = field(default_factory=Counter)
    warnings: list[str] = field(default_factory=list)


class _Builder:
    def __init__(self, steps: list[ScanStep], options: BackEndOptions) -> None:
        self.steps = steps
        self.options = options
        self.keyframe_steps = np.array([i for i, s in enumerate(steps) if s.keyframe or i == 0], dtype=np.int64)
        self.node_of = {int(step): node for node, step in enumerate(self.keyframe_steps)}
        self.graph = PoseGraph(np.asarray(steps[0].pose, dtype=np.float64), loop_kernel=options.loop_kernel,
                               kernel_width=options.kernel_width)
        self.search = LoopClosureSearch(options.loop) if options.loop is not None else None
        self.check = ConsistencyCheck(options.loop, self.search.path_m) if self.search is not None else None
        self.candidates: list[LoopCandidate] = []
        self.optimizations: list[Optimization] = []
        self.counts: Counter = Counter()
        self.warnings: list[str] = []
        self._loops_since_optimization = 0
        self._last_optimization = 0
        self._edges: list[tuple[int, int, float]] = []  # (i, j, weight) of every constraint, for the graph distances

    def run(self) -> BackEndResult:
        keyframes = enumerate(self.keyframe_steps)
        desc = "loop closure" if self.search is not None else "pose graph"
        for node, step in progress(keyframes, total=len(self.keyframe_steps), desc=desc, unit="keyframe"):
            motion, covariance = self._add_node(node, int(step))
            if self.search is not None:
                self.search.add_keyframe(self.steps[int(step)].points_base, motion, covariance)
                self._close_loops(node)
        if self.check is not None:
            self._follow_up_backwards()
            self.check.flush()
            self._judge_unconfirmed()
        self._optimize(node=len(self.keyframe_steps) - 1)
        if self.counts["unlinked keyframes"]:
            self.warnings.append(f"{self.counts['unlinked keyframes']} keyframe(s) had no match against the keyframe "
                                 "before them: linked by their front-end poses with an uncertainty of 1 m, 0.55 rad")
        if self.counts["odometry covariances repaired"]:
            self.warnings.append(f"{self.counts['odometry covariances repaired']} odometry covariance(s) were not "
                                 "positive definite: their eigenvalues were raised to 1e-8")
        return BackEndResult(self.graph, self.keyframe_steps, self.candidates, self.optimizations, self.counts,
                             self.warnings)

    # -- nodes and odometry edges --------------------------------------------------------------

    def _add_node(self, node: int, step: int) -> tuple[np.ndarray | None, np.ndarray | None]:
        """Add keyframe ``node`` with its odometry edge; returns its motion from the node before and the edge's
        covariance (None, None for the first)."""
        if node == 0:
            return None, None
        s = self.steps[step]
        ref = self.node_of.get(int(s.reference))
        if ref is None or s.reference < 0:
            ref = node - 1
            T = se2_between(self.steps[int(self.keyframe_steps[ref])].pose, s.pose)
            cov = UNLINKED_COVARIANCE
            self.counts["unlinked keyframes"] += 1
        else:
            T = np.asarray(s.T_ref_cur, dtype=np.float64)
            cov = self._odometry_covariance(s.covariance)
        pose = se2_compose(self.graph.poses[ref], T)
        pose[2] = wrap_to_pi(pose[2])
        self.graph.add_node(pose)
        self.graph.add(Constraint(ref, node, T, cov, ODOMETRY))
        if ref == node - 1:
            return T, cov
        return se2_between(self.graph.poses[node - 1], pose), cov

    def _odometry_covariance(self, covariance: np.ndarray) -> np.ndarray:
        try:
            return check_covariance(covariance, "odometry")
        except ValueError:
            cov = np.asarray(covariance, dtype=np.float64)
            if cov.shape != (3, 3) or not np.isfinite(cov).all():
                self.counts["unlinked keyframes"] += 1
                return UNLINKED_COVARIANCE
            values, vectors = np.linalg.eigh(0.5 * (cov + cov.T))
            self.counts["odometry covariances repaired"] += 1
            return (vectors * np.maximum(values, 1e-8)) @ vectors.T

    # -- loops ---------------------------------------------------------------------------------

    def _edge_weight(self, c: Constraint) -> float:
        o = self.options.loop
        if c.kind == LOOP:
            return o.loop_edge_m
        length = float(np.hypot(c.T_i_j[0], c.T_i_j[1]) + o.turn_m_per_rad * abs(c.T_i_j[2]))
        sd = np.sqrt(np.diag(c.covariance))
        if max(sd[0], sd[1]) > LOOSE_EDGE_M or sd[2] > LOOSE_EDGE_RAD:
            # an edge the front end is unsure of (an ambiguous step, an unlinked keyframe) is as uncertain as
            # this much path: loops across it are searched in windows that cover it
            length += max(max(sd[0], sd[1]) / o.drift_per_m, sd[2] / o.drift_rad_per_m)
        return max(length, 1e-6)  # a zero weight would read as no edge

    def _graph_distance(self, node: int) -> np.ndarray:
        """Graph distance (m) from ``node`` to every node (see the module docstring)."""
        cons = self.graph.constraints
        for c in cons[len(self._edges):]:
            self._edges.append((c.i, c.j, self._edge_weight(c)))
        n = self.graph.n_nodes
        if not self._edges:
            return np.where(np.arange(n) == node, 0.0, np.inf)
        edges = np.array(self._edges).reshape(-1, 3)
        i, j = np.minimum(edges[:, 0], edges[:, 1]).astype(np.int64), np.maximum(edges[:, 0], edges[:, 1]).astype(np.int64)
        # of parallel edges the lightest (a sparse matrix would add them up)
        order = np.lexsort((edges[:, 2], j, i))
        first = np.r_[True, (np.diff(i[order]) != 0) | (np.diff(j[order]) != 0)]
        keep = order[first]
        adjacency = csr_matrix((edges[keep, 2], (i[keep], j[keep])), shape=(n, n))
        return dijkstra(adjacency, directed=False, indices=node)

    def _close_loops(self, node: int) -> None:
        o = self.options
        accepted_pairs = [(c.old, c.new) for c in self.check.accepted]
        distance = self._graph_distance(node)
        for old in self.search.candidates(node, self.graph.poses, distance, accepted_pairs):
            sigma_t, sigma_r = self.search.sigmas(distance[old])
            cand = self.search.match(old, node, self.graph.poses, (float(sigma_t), float(sigma_r)))
            self.candidates.append(cand)
            if cand.T_old_new is None:
                continue
            for c in self.check.review(cand, self.graph.poses):
                self._add_loop(c)
        self._follow_up(node, distance)
        last_loop = max((c.new for c in self.check.accepted), default=None)
        if self.search.global_due(node, last_loop):
            self._global_search(node, distance)
        self.check.expire(node)
        due = self._loops_since_optimization and node - self._last_optimization >= o.optimize_every
        if self.counts["large corrections"] or due:
            self._optimize(node)

    def _global_search(self, node: int, distance: np.ndarray) -> None:
        """Match ``node`` against old maps anywhere (``distance``: graph distances from ``node``, m); the best match
        enters the graph when an accepted loop agrees with it, and otherwise waits for a follow-up."""
        self.counts["global searches"] += 1
        matches = []
        for old in self.search.global_tiles(node, self.graph.poses):
            sigma_t, sigma_r = self.search.sigmas(distance[old])
            cand = self.search.match(old, node, self.graph.poses, (float(sigma_t), float(sigma_r)),
                                     kind=LoopKind.GLOBAL)
            self.counts["global matches tried"] += 1
            if cand.T_old_new is not None:
                matches.append(cand)
            elif cand.status == LoopOutcome.LOOK_ALIKE:
                self.counts["global look-alikes refused"] += 1
        if matches:
            best = max(matches, key=lambda c: c.score)
            self.candidates.append(best)  # judged against the graph's drift model, then waits or is confirmed
            for c in self.check.review(best, self.graph.poses):  # confirmed at once by an accepted loop, or waits
                self._add_loop(c)

    def _follow_up(self, node: int, distance: np.ndarray) -> None:
        """Match ``node`` where each pending match (but look-alikes) puts it, once its new map shares no keyframe
        with the match's (the old chain, the match, the new chain); a consistent follow-up confirms the pair."""
        o = self.options.loop
        for p in self.check.to_follow_up():
            if node - p.new > o.new_map_keyframes:
                self._follow_up_at(p, node)

    def _follow_up_backwards(self) -> None:
        """At the end of the run no keyframe comes after the matches still waiting: each is followed up at the
        keyframes before it instead, from the nearest whose new map shares none of its keyframes back, over
        ``pending_keyframes``, until one confirms it. The evidence is the same: the old chain, the match, and
        the new chain between the two keyframes."""
        o = self.options.loop
        for p in self.check.to_follow_up():
            for node in range(p.new - o.new_map_keyframes - 1, max(p.new - o.pending_keyframes, 0) - 1, -1):
                if p.status != LoopOutcome.PENDING or self._follow_up_at(p, node):
                    break

    def _follow_up_at(self, p: LoopCandidate, node: int) -> bool:
        """Match ``node`` where the pending match ``p`` puts it; True if that confirmed a pair."""
        poses = self.graph.poses
        guess = se2_compose(p.T_old_new, se2_between(poses[p.new], poses[node]))
        sigma_t, sigma_r = self.search.sigmas(abs(self.search.path_m[node] - self.search.path_m[p.new]))
        cand = self.search.match(p.old, node, poses, (float(sigma_t), float(sigma_r)), guess=guess,
                                 kind=LoopKind.FOLLOW_UP)
        cand.follows = p
        self.candidates.append(cand)
        if cand.T_old_new is None:
            return False
        accepted = self.check.review(cand, poses)
        for c in accepted:
            self._add_loop(c)
        return bool(accepted)

    def _judge_unconfirmed(self) -> None:
        """The matches no second one confirmed (but look-alikes and follow-ups, which repeat their match's error)
        are handed to the graph: those GTSAM's graduated non-convexity takes as inliers, with the graph's
        constraints as known inliers and the outlier gate as the inlier threshold, are accepted."""
        doubtful = [c for c in self.candidates if c.status == LoopOutcome.UNCONFIRMED and c.T_old_new is not None
                    and c.look_alike is not True and c.kind != LoopKind.FOLLOW_UP]
        if not doubtful:
            return
        _, chi2 = self.graph.loop_chi2()
        inliers = self.graph.judge([Constraint(c.old, c.new, c.T_old_new, c.covariance, LOOP) for c in doubtful],
                                   self.outlier_gate(chi2))
        for cand, inlier in zip(doubtful, inliers):
            if inlier:
                cand.status = LoopOutcome.ACCEPTED
                self.check.accepted.append(cand)
                self._add_loop(cand)
                self.counts[TAKEN_BY_GRAPH] += 1

    def _add_loop(self, cand: LoopCandidate) -> None:
        self.graph.add(Constraint(cand.old, cand.new, cand.T_old_new, cand.covariance, LOOP))
        self._loops_since_optimization += 1
        residual = se2_between(se2_between(self.graph.poses[cand.old], self.graph.poses[cand.new]), cand.T_old_new)
        if np.hypot(residual[0], residual[1]) > self.options.correction_m or abs(residual[2]) > self.options.correction_rad:
            self.counts["large corrections"] += 1

    def outlier_gate(self, chi2: np.ndarray) -> float:
        """The chi2 above which a loop is an outlier: ``outlier_chi2``, scaled up by the loops' own spread.

        The matchers' covariances share an unknown scale (a scan's points are not
        independent, so the Hessians are too sure). The median of the loops' chi2
        over the median of a chi2 of 3 degrees of freedom (2.366) estimates that
        scale robustly, as the MAD does for a standard deviation; with fewer than
        ``min_loops_for_scale`` loops, or a scale below 1, the gate is as given.
        """
        scale = 1.0
        if len(chi2) >= self.options.min_loops_for_scale:
            scale = max(1.0, float(np.median(chi2)) / CHI2_3DOF_MEDIAN)
        return self.options.outlier_chi2 * scale

    def _supported(self, loop: Constraint) -> bool:
        """Does another accepted loop, from a new map sharing no keyframe with this one's, agree with it (the
        cycle through the two short chains closes)? Such a pair is two pieces of evidence against the long
        odometry chain, whose drift the chi2 does not know."""
        if self.check is None:
            return False
        cands = [c for c in self.check.accepted if c.old == loop.i and c.new == loop.j]
        return bool(cands) and self.check.supported(cands[0], self.graph.poses)

    def _optimize(self, node: int) -> None:
        """Optimize; then drop the worst loop above the chi2 gate and optimize again, until none is."""
        self.optimizations.append(self.graph.optimize())
        for _ in range(self.options.max_outlier_rounds):
            loops, chi2 = self.graph.loop_chi2()
            if not loops:
                break
            gate = self.outlier_gate(chi2)
            above = [k for k in np.argsort(-chi2, kind="stable") if chi2[k] > gate]
            drop = next((k for k in above if not self._supported(self.graph.constraints[loops[k]])), None)
            if drop is None:
                break
            worst = self.graph.constraints[loops[drop]]
            self.graph.remove([loops[drop]])
            self._edges = []  # the graph distances are rebuilt from the remaining constraints
            for cand in self.check.accepted:
                if cand.old == worst.i and cand.new == worst.j and cand.status == LoopOutcome.ACCEPTED:
                    cand.status = LoopOutcome.OUTLIER
            self.check.accepted = [c for c in self.check.accepted if c.status == LoopOutcome.ACCEPTED]
            self.optimizations.append(self.graph.optimize())
        self.counts.pop("large corrections", None)
        self._loops_since_optimization = 0
        self._last_optimization = node


def build_pose_graph(steps: list[ScanStep], options: BackEndOptions | None = None) -> BackEndResult:
    """The optimized pose graph of the front end's ``steps`` (see the module docstring).

    Nodes are the keyframes (the first step always is one); ``steps`` must hold at least one step.
    """
    if not steps:
        raise ValueError("no steps: the front end registered no scan")
    return _Builder(steps, options or BackEndOptions()).run()


__all__ = ["BackEndOptions", "BackEndResult", "TAKEN_BY_GRAPH", "build_pose_graph"]
