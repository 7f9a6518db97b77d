"""Settings of the laser odometry (:class:`FrontEndOptions`) and what they are derived from in a bag's scans
(:func:`cell_size_for`)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from enum import StrEnum
from typing import Any

import numpy as np

from bagtools.errors import BagtoolsError
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


INIT_MODES = ("auto", *GUESSES)
REFERENCE_MODES = ("previous", "keyframe")
#: What no ground robot does (m/s, rad/s): a --max-speed or --max-turn-rate beyond is a typo, not a robot.
MAX_PLAUSIBLE_SPEED_MPS, MAX_PLAUSIBLE_TURN_RATE_RADPS = 100.0, 50.0


@dataclass(frozen=True)
class NdtOdomOptions:
    """How to run laser odometry (the defaults are the ones to use; the rest is for experts).

    ``init``: the guess NDT starts from first ('auto': the odometry when the bag
    has it, else constant velocity). ``search``: allow the grid search when a
    guess cannot be trusted. ``use_odometry``: False ignores the bag's wheel
    odometry. ``cell_size_m``: NDT cell side (m), None for one suited to the
    scans (:func:`~bagtools.odometry.options.cell_size_for`). ``cell_model``: 'widened'
    (see :mod:`bagtools.scan_matching.grid`) or 'paper'. ``min_score``: normalized score
    in [0, 1] below which a match falls back to its guess.
    ``scan_frame_offset``: (x m, y m, yaw rad) of the laser on the robot base,
    overriding (or standing in for) tf. ``max_speed_mps`` and
    ``max_turn_rate_radps``: what the robot can do (bounds constant velocity
    and the search). ``wheeled``: False for a handheld or flying laser (its
    steps need not run along arcs, see :class:`~bagtools.odometry.options.FrontEndOptions`).
    """

    topic: str = "/scan"
    init: str = "auto"
    search: bool = True
    use_odometry: bool = True
    reference: str = "keyframe"
    cell_size_m: float | None = None
    cell_model: str = "widened"
    min_score: float = 0.1
    keyframe_distance_m: float = 0.5
    keyframe_angle_rad: float = 0.35
    keyframe_score_ratio: float = 0.7
    scan_frame_offset: tuple[float, float, float] | None = None
    max_speed_mps: float = FrontEndOptions.max_speed_mps
    max_turn_rate_radps: float = FrontEndOptions.max_turn_rate_radps
    wheeled: bool = True
    max_iterations: int = 100

    def __post_init__(self) -> None:
        if self.init not in INIT_MODES:
            raise BagtoolsError(f"--init must be one of {', '.join(INIT_MODES)}, got {self.init!r}")
        if self.reference not in REFERENCE_MODES:
            raise BagtoolsError(f"--reference must be one of {', '.join(REFERENCE_MODES)}, got {self.reference!r}")
        if self.cell_size_m is not None and not (np.isfinite(self.cell_size_m) and self.cell_size_m > 0):
            raise BagtoolsError(f"--cell-size must be a positive number of metres, got {self.cell_size_m}")
        if self.cell_model not in CELL_MODELS:
            raise BagtoolsError(f"--cell-model must be one of {', '.join(CELL_MODELS)}, got {self.cell_model!r}")
        if not 0.0 <= self.min_score <= 1.0:
            raise BagtoolsError(f"--min-score must be in [0, 1] (a normalized NDT score), got {self.min_score}")
        if self.keyframe_distance_m <= 0 or self.keyframe_angle_rad <= 0 or not 0 <= self.keyframe_score_ratio <= 1:
            raise BagtoolsError("keyframe thresholds must be positive (score ratio in [0, 1])")
        if self.scan_frame_offset is not None and (len(self.scan_frame_offset) != 3
                                                   or not np.isfinite(self.scan_frame_offset).all()):
            raise BagtoolsError(f"--scan-frame-offset must be three numbers X,Y,YAW, got {self.scan_frame_offset!r}")
        for name, flag, most in (("max_speed_mps", "--max-speed", MAX_PLAUSIBLE_SPEED_MPS),
                                 ("max_turn_rate_radps", "--max-turn-rate", MAX_PLAUSIBLE_TURN_RATE_RADPS)):
            value = getattr(self, name)
            if not (math.isfinite(value) and 0 < value <= most):
                raise BagtoolsError(f"{flag} must be a positive number no robot exceeds (at most {most:g}), got {value}")
        if self.max_iterations < 1:
            raise BagtoolsError(f"max_iterations must be at least 1, got {self.max_iterations}")

    @classmethod
    def from_params(cls, p: Mapping[str, Any]) -> NdtOdomOptions:
        """The options ``bagtools ndt-odom`` was given: its click parameters by name (the command and its batch job
        build them here, so the two cannot differ)."""
        return cls(topic=p["topic"], init=p["init"], search=not p["no_search"], use_odometry=not p["no_odometry"],
                   reference=p["reference"], cell_size_m=p["cell_size"], cell_model=p["cell_model"],
                   min_score=p["min_score"], max_speed_mps=p["max_speed"], max_turn_rate_radps=p["max_turn_rate"],
                   wheeled=not p["holonomic"], scan_frame_offset=p["scan_frame_offset"])

    def front_end(self, cell_size_m: float) -> FrontEndOptions:
        """The settings of the :class:`~bagtools.odometry.frontend.LaserOdometry` these options ask for
        (``cell_size_m`` when the options leave it to the scans)."""
        cell = self.cell_size_m if self.cell_size_m is not None else cell_size_m
        return FrontEndOptions(init=self.init, search=self.search, reference=self.reference,
                               cell_size_m=cell, voxel_m=cell * VOXEL_PER_CELL, cell_model=self.cell_model,
                               min_score=self.min_score,
                               keyframe_distance_m=self.keyframe_distance_m, keyframe_angle_rad=self.keyframe_angle_rad,
                               keyframe_score_ratio=self.keyframe_score_ratio, max_speed_mps=self.max_speed_mps,
                               max_turn_rate_radps=self.max_turn_rate_radps, wheeled=self.wheeled,
                               max_iterations=self.max_iterations)


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


class StepEvent(StrEnum):
    """What the front end counts of its steps (:meth:`~bagtools.odometry.frontend.LaserOdometry.summary_counts`
    gives each its summary.json key; its warnings say each in a line)."""

    SEARCHED = "searched"
    FALLBACK = "fallback"
    ODOM_REJECTED = "odometry_rejected"
    TOO_FAST = "faster_than_robot"
    AMBIGUOUS = "ambiguous"
    BEYOND_REACH = "beyond_reach"
    REVISED = "revised_by_the_next_scan"


#: A step is ambiguous when another place scores within this much of the chosen one (normalized score less the
#: prior's cost); more than AMBIGUOUS_WARN_SHARE of the pairs (and at least 3) is said in a warning.
AMBIGUOUS_MARGIN = 0.05
AMBIGUOUS_WARN_SHARE = 0.03
#: Candidates in distinct places whose objectives are within CONTEST_MARGIN of the best are decided on a finer
#: grid: each is scored as a likelihood field of the keyframe's submap at FINE_SCORE_RESOLUTION_M (the best pose
#: within FINE_SCORE_WINDOW of it), less the cost of the motion under what the robot can do (the prior's wide
#: part: the narrow part's preference already shortlisted them). Coarse NDT cells blur what tells a sharp turn or
#: a half-seen room or a corridor's doors from a look-alike; a fine grid does not.
CONTEST_MARGIN = 0.1
#: How much a robot's heading may change per metre travelled (rad/m, one sigma) beyond constant velocity's turn: the
#: wide search starts NDT at headings across it (a robot turns into a side corridor within a metre).
CV_TURN_PER_M = 0.3
FINE_SCORE_RESOLUTION_M = 0.05
FINE_SCORE_WINDOW = (0.1, 0.1, 0.02)
#: Added to an ambiguous step's covariance (m^2, m^2, rad^2): the other place may be the right one, and a pose
#: graph built on the steps must be free to bend there (and to search loops across it widely).
AMBIGUOUS_COVARIANCE = np.diag([0.3**2, 0.3**2, 0.5**2])


#: A step whose match scores under this share of the typical score does not show the scene going on from the
#: keyframe's (``ScanStep.trusted`` is False): a robot carried away matches nothing of it (a fallback, at 0.1 of the
#: typical score on simulated kidnaps), while a scan merely harder to match scores 0.6 of it or more.
CONTINUITY_SCORE_RATIO = 0.5
#: A scan of fewer points (voxel-filtered) is not searched beyond the prior's window: a dozen returns fit somewhere in
#: any large window as well as at the place, and could not overrule the motion model.
MIN_WIDE_POINTS = 20
#: Keyframes of the submap lie within this distance of the newest one (m).
SUBMAP_RADIUS_M = 10.0
#: The search window spans this many prior sigmas (never more than MAX_SEARCH_M).
SEARCH_SIGMAS = 3.0
MAX_SEARCH_M = 3.0
#: The refinement's cells are this share of the matching cells (half the area), when at least MIN_REFINE_CELL_M;
#: it may move the pose by at most REFINE_MAX_M and REFINE_MAX_RAD.
REFINE_CELL_RATIO = 1.0 / math.sqrt(2.0)
MIN_REFINE_CELL_M = 0.5
REFINE_MAX_M, REFINE_MAX_RAD = 0.2, 0.05
#: Where the finer grid barely constrains a direction of translation (its Hessian's eigenvalues there under this
#: share of the largest: a corridor), the refinement's move along it is not taken: the fine cost is flat there,
#: and the pose would slide along the corridor on noise (the coarse match's prior decided that direction).
DEGENERATE_RATIO = 0.02
#: The wide search (what the robot can have done) matches against the keyframes within SUBMAP_RADIUS_M, up to this
#: many: after a sharp turn or a gap the scan may see what only older keyframes saw, and a small submap can match a
#: repeated scene (a parallel corridor, the mirror image of a junction) better than the place itself.
WIDE_SUBMAP_KEYFRAMES = 15
#: Its distinct correlative peaks (at least this share of the best) are refined by NDT and weighed by the prior.
WIDE_PEAKS, WIDE_PEAK_RATIO = 8, 0.6
#: A peak whose prior cost (weighted, in normalized score) exceeds this could not win: it is not refined.
WIDE_MAX_PRIOR_COST = 0.5
#: Without odometry, when every match within reach scores below the trust score and the time step is shorter
#: than SHORT_STEP_RATIO of the recent typical one (its stamp is suspect: a log resampled from another clock puts
#: 0.15 s on a 30-degree turn), the largest window (MAX_SEARCH_M, any heading, around the previous pose) is
#: searched with no reach at all. A match there is taken when it scores at least the trust score and
#: BEYOND_REACH_GAIN more than the best within reach. A step over 1 / SHORT_STEP_RATIO of the typical one (and
#: over ``max_gap_s``) is a gap: the robot may have done anything meanwhile.
SHORT_STEP_RATIO = 0.25
BEYOND_REACH_GAIN = 0.2


#: Guesses closer than this to a result (m, rad) lie in its basin: NDT from them would end there too.
BASIN_M, BASIN_RAD = 0.15, 0.1
#: Two results closer than this (m, rad) agree.
AGREE_M, AGREE_RAD = 0.05, 0.02


__all__ = ["CELL_PER_RANGE", "GUESSES", "INIT_MODES", "MAX_PLAUSIBLE_SPEED_MPS", "MAX_PLAUSIBLE_TURN_RATE_RADPS",
           "NdtOdomOptions", "REFERENCE_MODES", "MAX_AUTO_CELL_M", "MIN_AUTO_CELL_M", "VOXEL_PER_CELL", "FrontEndOptions",
           "cell_size_for", "normalized_score"]
