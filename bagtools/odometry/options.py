"""Settings of the laser odometry (:class:`FrontEndOptions`) and what they are derived from in a bag's scans
(:func:`cell_size_for`)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from bagtools.odometry.motion import PRIOR_WEIGHT_DEFAULT
from bagtools.scan_matching.grid import CELL_MODELS

GUESSES = ("odom", "constant-velocity", "zero")

@dataclass(frozen=True)
class FrontEndOptions:
    """Settings of :class:`LaserOdometry` (defaults hold on the real logs and on simulated bags).

    ``init``: which guess NDT starts from first ("auto": odometry when given,
    else constant velocity). ``search``: allow the grid search. ``reference``:
    "keyframe" or "previous" (every scan is a keyframe). ``wheeled``: the scans
    ride on a wheeled robot, whose steps run along arcs (False for a handheld
    or flying laser, which can move sideways). ``refine``: the finer-grid
    refinement of large-cell scenes (step 4 of the module docstring).
    """

    init: str = "auto"
    search: bool = True
    reference: str = "keyframe"
    cell_size_m: float = 1.0
    cell_model: str = "widened"
    min_score: float = 0.1
    trust_score_ratio: float = 0.75
    keyframe_distance_m: float = 0.5
    keyframe_angle_rad: float = 0.35
    keyframe_score_ratio: float = 0.7
    max_speed_mps: float = 1.5
    max_turn_rate_radps: float = 2.0
    max_accel_mps2: float = 1.0
    max_turn_accel_radps2: float = 2.0
    max_gap_s: float = 1.5
    search_resolution_m: float = 0.1
    search_angular_resolution_rad: float = 0.005
    submap_keyframes: int = 5
    prior_weight: float = PRIOR_WEIGHT_DEFAULT
    voxel_m: float = 0.2
    wheeled: bool = True
    max_iterations: int = 100
    refine: bool = True

    def __post_init__(self) -> None:
        if self.init not in ("auto", *GUESSES):
            raise ValueError(f"init must be auto or one of {', '.join(GUESSES)}, got {self.init!r}")
        if self.reference not in ("keyframe", "previous"):
            raise ValueError(f"reference must be keyframe or previous, got {self.reference!r}")
        if self.cell_model not in CELL_MODELS:
            raise ValueError(f"cell_model must be one of {', '.join(CELL_MODELS)}, got {self.cell_model!r}")
        for name in ("cell_size_m", "max_speed_mps", "max_turn_rate_radps", "max_accel_mps2", "max_turn_accel_radps2",
                     "max_gap_s", "search_resolution_m", "search_angular_resolution_rad", "keyframe_distance_m",
                     "keyframe_angle_rad"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a positive number, got {value}")
        if not 0.0 <= self.min_score <= 1.0 or not 0.0 <= self.trust_score_ratio <= 1.0:
            raise ValueError("min_score and trust_score_ratio must be in [0, 1]")


#: The scans are voxel-filtered at this share of the NDT cell size.
VOXEL_PER_CELL = 0.2
#: cell_size_for: the cell is this share of the 90th percentile of the ranges, within the limits.
CELL_PER_RANGE, MIN_AUTO_CELL_M, MAX_AUTO_CELL_M = 1.0 / 6.0, 0.5, 1.0


def cell_size_for(scans_points: list[np.ndarray]) -> float:
    """An NDT cell size (m) suited to the scans (each (N,2) in its sensor's frame): a sixth of the 90th
    percentile range, within 0.5 m (a small room) and 1 m (a corridor seen 20 m deep)."""
    sample = scans_points[:: max(1, len(scans_points) // 50)]
    ranges = np.concatenate([np.hypot(p[:, 0], p[:, 1]) for p in sample]) if sample else np.zeros(0)
    if ranges.size == 0:
        return MIN_AUTO_CELL_M
    return float(np.clip(CELL_PER_RANGE * np.percentile(ranges, 90), MIN_AUTO_CELL_M, MAX_AUTO_CELL_M))


def normalized_score(score: float, n_points: int) -> float:
    """NDT score / its maximum (4 grids x points): in [0, 1] whatever the beam count."""
    return score / (4.0 * n_points) if n_points > 0 else 0.0




__all__ = ["CELL_PER_RANGE", "GUESSES", "MAX_AUTO_CELL_M", "MIN_AUTO_CELL_M", "VOXEL_PER_CELL", "FrontEndOptions",
           "cell_size_for", "normalized_score"]
