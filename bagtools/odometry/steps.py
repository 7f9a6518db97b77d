"""What the laser-odometry front end hands on: one registered scan per step, and the run's counts.

``ndt-odom`` writes these as its trajectory; ``slam`` builds its pose graph from
them: the keyframes are its nodes, and each keyframe's match against the
keyframe before it (``reference``, ``T_ref_cur``, ``covariance``) is an
odometry edge.

Poses are planar [x, y, theta] (m, m, rad) of the robot base; ``pose`` is in
the odometry frame of the front end (the wheel odometry's frame when the bag
has one, else the first scan's base pose is the origin).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class ScanStep:
    """One scan registered by the front end.

    Attributes:
        stamp_ns: the scan's header stamp, int ns.
        pose: (3,) [x, y, theta] of the robot base in the odometry frame.
        points_base: (N,2) the scan's valid returns in the base frame (laser mount applied), metres.
        reference: index (into the steps) of the keyframe this scan was matched against; -1 for the first.
        T_ref_cur: (3,) [x, y, theta] of this scan's base in the reference keyframe's base frame, as matched.
        covariance: (3,3) covariance of ``T_ref_cur`` (m^2, m rad, rad^2), from the matcher.
        score: normalized NDT score of the final match, in [0, 1] (1.0 for the first scan).
        source: how the pose was found: "first", "ndt" (from the best guess), "search" (a grid search
            seeded NDT), or "fallback" (no match could be trusted: the guess was kept).
        keyframe: this scan became the reference for the scans after it.
        ambiguous: another place, outside NDT's basin, matched almost as well (see
            :data:`bagtools.odometry.options.AMBIGUOUS_MARGIN`): the step may be wrong, and its
            ``covariance`` says so (:data:`bagtools.odometry.options.AMBIGUOUS_COVARIANCE` added).
        trusted: the scene went on from the keyframe's, so the robot was not carried away between them: no
            fallback, no jump beyond reach, not ambiguous, and a score of at least
            :data:`bagtools.odometry.options.CONTINUITY_SCORE_RATIO` of the typical.
    """

    stamp_ns: int
    pose: np.ndarray
    points_base: np.ndarray
    reference: int
    T_ref_cur: np.ndarray
    covariance: np.ndarray
    score: float
    source: str
    keyframe: bool
    ambiguous: bool = False
    trusted: bool = True


@dataclass
class FrontEndRun:
    """The front end's output: ``steps`` in scan order, counts by kind (for summary.json) and warnings."""

    steps: list[ScanStep] = field(default_factory=list)
    counts: dict[str, int] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)

    @property
    def keyframe_indexes(self) -> list[int]:
        return [i for i, s in enumerate(self.steps) if s.keyframe]

    def stamps_ns(self) -> np.ndarray:
        return np.array([s.stamp_ns for s in self.steps], dtype=np.int64)

    def poses(self) -> np.ndarray:
        """(N,3) [x, y, theta] of every step."""
        return np.array([s.pose for s in self.steps]).reshape(-1, 3)
