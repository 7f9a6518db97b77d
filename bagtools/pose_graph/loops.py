"""What the loop search produces and is set by: its options (:class:`LoopOptions`), each candidate's record
(:class:`LoopCandidate`) and the outcomes and kinds summary.json counts. The search is
:mod:`bagtools.pose_graph.constraints`; the acceptance :mod:`bagtools.pose_graph.consistency`."""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import StrEnum

import numpy as np

from bagtools.transforms import se2_between


class LoopOutcome(StrEnum):
    """What became of a loop candidate: its ``status`` (summary.json counts candidates by these words)."""

    ACCEPTED = "accepted"
    PENDING = "pending"
    LOW_SCORE = "score below min_score"
    REFINE_FAILED = "NDT refinement failed or moved away"
    INCONSISTENT = "disagrees with the estimate"
    UNCONFIRMED = "unconfirmed: no consistent second match"
    OUTLIER = "outlier after optimization"
    TOO_FEW_POINTS = "too few points"
    LOOK_ALIKE = "a look-alike elsewhere in the window scores as well"
    SEES_THROUGH = "walls where the other map saw through"


class LoopKind(StrEnum):
    """Where a candidate was searched: around the estimate, anywhere, or around a pending global match."""

    LOCAL = "local"
    GLOBAL = "global"
    FOLLOW_UP = "follow-up"


@dataclass(frozen=True)
class LoopOptions:
    """Settings of the loop-closure search (see the module docstring; metres, radians).

    The drift rates are the laser odometry's error growth, one sigma per metre
    of graph distance; they size the search reach, the window and the gates.
    """

    search_radius_m: float = 5.0
    min_travel_m: float = 8.0
    drift_per_m: float = 0.03
    drift_rad_per_m: float = 0.01
    loop_edge_m: float = 1.0
    turn_m_per_rad: float = 0.5
    gate_sigmas: float = 3.0
    min_window_m: float = 0.3
    min_window_rad: float = 0.1
    resolution_m: float = 0.1
    angular_reach_m: float = 10.0
    max_range_m: float = 20.0
    max_points: int = 1500
    min_score: float = 0.5
    old_map_keyframes: int = 3
    new_map_keyframes: int = 4
    max_candidates: int = 2
    wide_window_m: float = 2.0
    wide_spacing_m: float = 2.0
    loop_spacing_m: float = 1.0
    sure_sigma_m: float = 0.3
    pending_keyframes: int = 20
    pair_max_path_m: float = 15.0
    ndt_cell_m: float = 0.5
    max_refine_m: float = 0.3
    max_refine_rad: float = 0.1
    max_seen_through: float = 0.1
    cache_size: int = 64
    global_after_m: float = 30.0
    global_tile_m: float = 4.0
    global_window_m: float = 4.0
    global_min_score: float = 0.6
    global_max_tiles: int = 32
    global_unique_ratio: float = 0.9
    global_gate_sigmas: float = 5.0
    global_separation_m: float = 1.0
    global_separation_rad: float = 0.3

    def __post_init__(self) -> None:
        for name in ("search_radius_m", "min_travel_m", "wide_window_m", "wide_spacing_m", "drift_per_m",
                     "drift_rad_per_m", "loop_edge_m", "angular_reach_m", "gate_sigmas", "min_window_m", "min_window_rad",
                     "resolution_m", "max_range_m", "loop_spacing_m", "sure_sigma_m", "pair_max_path_m", "ndt_cell_m",
                     "max_refine_m", "max_refine_rad", "global_after_m", "global_tile_m", "global_window_m",
                     "global_separation_m", "global_separation_rad", "global_gate_sigmas"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a positive number, got {value!r}")
        for name in ("min_score", "global_min_score", "global_unique_ratio", "max_seen_through"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ValueError(f"{name} must be in [0, 1], got {getattr(self, name)!r}")
        for name in ("max_points", "max_candidates", "pending_keyframes", "cache_size", "global_max_tiles"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be at least 1, got {getattr(self, name)!r}")
        if self.old_map_keyframes < 0 or self.new_map_keyframes < 0 or self.turn_m_per_rad < 0:
            raise ValueError("old_map_keyframes, new_map_keyframes and turn_m_per_rad must not be negative")


@dataclass
class LoopCandidate:
    """One loop-closure candidate: old keyframe ``old`` seen again from new keyframe ``new`` (node numbers).

    ``guess``: the estimated pose of ``new`` in ``old``'s frame when searched;
    ``window``: the search half-widths (m, m, rad); ``sigma``: the estimate's
    uncertainty of it (m, rad); ``T_old_new``, ``covariance``: the match (None
    when it failed); ``score``: correlative score in [0, 1]; ``status``:
    a :class:`LoopOutcome`: accepted, pending or why it was rejected; ``time_s``: match time;
    ``kind``: a :class:`LoopKind`: local (around the estimate), global (anywhere) or follow-up (around a pending global
    match).
    """

    old: int
    new: int
    guess: np.ndarray
    window: np.ndarray
    sigma: tuple[float, float]
    T_old_new: np.ndarray | None = None
    covariance: np.ndarray | None = None
    score: float = 0.0
    status: LoopOutcome = LoopOutcome.PENDING
    time_s: float = 0.0
    kind: LoopKind = LoopKind.LOCAL
    look_alike: bool | None = None  # another place of the window scores as well (None: the window was not asked)
    follows: LoopCandidate | None = None  # for a follow-up: the match it was searched around

    def as_dict(self) -> dict:
        out = {"old": self.old, "new": self.new, "kind": self.kind, "status": self.status, "score": round(self.score, 4),
               "sigma_m": round(self.sigma[0], 4), "sigma_rad": round(self.sigma[1], 4),
               "window": [round(float(v), 4) for v in self.window], "time_ms": round(self.time_s * 1e3, 2)}
        if self.T_old_new is not None:
            out["T_old_new"] = [round(float(v), 5) for v in self.T_old_new]
            out["correction_m"] = round(float(np.hypot(*se2_between(self.guess, self.T_old_new)[:2])), 4)
        return out


