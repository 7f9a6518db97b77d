"""Acceptance of loop matches (:class:`ConsistencyCheck`): against the estimate, and, when it is unsure, against an
independent second match (step 4 of :mod:`bagtools.pose_graph.constraints`)."""

from __future__ import annotations

import math

import numpy as np

from bagtools.pose_graph.loops import LoopCandidate, LoopKind, LoopOptions, LoopOutcome
from bagtools.transforms import se2_between, se2_compose, wrap_to_pi


class ConsistencyCheck:
    """Accepts loop matches that agree with the estimate and, when it is unsure, with each other.

    ``path_m``: the keyframes' distances along the path (shared with
    :class:`LoopClosureSearch`, growing as keyframes arrive).
    """

    def __init__(self, options: LoopOptions, path_m: list[float]) -> None:
        self.options = options
        self.path_m = path_m
        self.pending: list[LoopCandidate] = []
        self.accepted: list[LoopCandidate] = []

    def gate(self, sigma: tuple[float, float], sigmas: float | None = None) -> tuple[float, float]:
        """Largest disagreement (m, rad) with an estimate of uncertainty ``sigma`` that passes, at ``sigmas``
        (default ``gate_sigmas``) of it."""
        o = self.options
        k = o.gate_sigmas if sigmas is None else sigmas
        return (k * sigma[0] + 2 * o.resolution_m, k * sigma[1] + 2 * o.resolution_m / o.angular_reach_m)

    def review(self, cand: LoopCandidate, poses: np.ndarray) -> list[LoopCandidate]:
        """Judge a matched candidate against the estimate ``poses``; returns the candidates accepted now."""
        o = self.options
        if cand.kind == LoopKind.GLOBAL:  # the estimate may be off by what the drift model allows, given a wide margin
            residual = se2_between(se2_between(poses[cand.old], poses[cand.new]), cand.T_old_new)
            gate_t, gate_r = self.gate(cand.sigma, o.global_gate_sigmas)
        else:
            residual = se2_between(cand.guess, cand.T_old_new)
            gate_t, gate_r = self.gate(cand.sigma)
        if np.hypot(residual[0], residual[1]) > gate_t or abs(wrap_to_pi(residual[2])) > gate_r:
            cand.status = LoopOutcome.INCONSISTENT
            return []
        if cand.kind == LoopKind.LOCAL and cand.sigma[0] <= o.sure_sigma_m:
            cand.status = LoopOutcome.ACCEPTED
            self.accepted.append(cand)
            return [cand]
        partners = [p for p in self.pending + self.accepted[-20:] if self._pair_consistent(cand, p, poses)]
        if not partners:
            cand.status = LoopOutcome.PENDING
            self.pending.append(cand)
            return []
        now = [cand] + [p for p in partners if p.status == LoopOutcome.PENDING]
        for c in now:
            c.status = LoopOutcome.ACCEPTED
            self.accepted.append(c)
        self.pending = [p for p in self.pending if p.status == LoopOutcome.PENDING]
        return now

    def supported(self, cand: LoopCandidate, poses: np.ndarray) -> bool:
        """Is another accepted match, searched independently of ``cand``, pairwise consistent with it at the
        estimate ``poses``? A follow-up and the match it was searched around are one piece of evidence here: a
        follow-up repeats its match's error, so it confirms a match enough to enter the graph, not against it."""
        def same_search(a: LoopCandidate, b: LoopCandidate) -> bool:
            return a.follows is b or b.follows is a or (a.follows is not None and a.follows is b.follows)
        return any(p is not cand and not same_search(cand, p) and self._pair_consistent(cand, p, poses)
                   for p in self.accepted)

    def _pair_consistent(self, a: LoopCandidate, b: LoopCandidate, poses: np.ndarray) -> bool:
        """Does the cycle a.old -> a.new -> b.new -> b.old -> a.old close within the gate?"""
        o = self.options
        path = self.path_m
        if abs(a.new - b.new) <= o.new_map_keyframes:  # their new maps share keyframes: one piece of evidence
            return False
        old_gap = abs(path[a.old] - path[b.old])
        new_gap = abs(path[a.new] - path[b.new])
        if old_gap > o.pair_max_path_m or new_gap > o.pair_max_path_m:
            return False
        # T_aold_anew should equal T_aold_bold (old chain) + T_bold_bnew (loop b) + T_bnew_anew (new chain).
        through_b = se2_compose(se2_compose(se2_between(poses[a.old], poses[b.old]), b.T_old_new),
                                se2_between(poses[b.new], poses[a.new]))
        cycle = se2_between(a.T_old_new, through_b)
        chain_m = old_gap + new_gap
        sigma_t = math.sqrt(2.0) * o.resolution_m + o.drift_per_m * chain_m
        sigma_r = math.sqrt(2.0) * o.resolution_m / o.angular_reach_m + o.drift_rad_per_m * chain_m
        return bool(np.hypot(cycle[0], cycle[1]) <= o.gate_sigmas * sigma_t
                    and abs(wrap_to_pi(cycle[2])) <= o.gate_sigmas * sigma_r)

    def to_follow_up(self) -> list[LoopCandidate]:
        """The matches waiting for a second one that a follow-up may give: those whose window was wide and held no
        look-alike. A follow-up is searched in a small window where the match puts the robot, so it repeats the
        match's error if the match had one: only a match that is the one good place of a wide window is worth it."""
        return [p for p in self.pending if p.kind != LoopKind.FOLLOW_UP and p.look_alike is False]

    def expire(self, newest: int) -> list[LoopCandidate]:
        """Reject pending matches older than ``pending_keyframes`` keyframes before ``newest``; returns them."""
        old = [p for p in self.pending if newest - p.new > self.options.pending_keyframes]
        for p in old:
            p.status = LoopOutcome.UNCONFIRMED
        self.pending = [p for p in self.pending if p.status == LoopOutcome.PENDING]
        return old

    def flush(self) -> list[LoopCandidate]:
        """At the end of the run: every match still pending is unconfirmed."""
        return self.expire(newest=10**12)
