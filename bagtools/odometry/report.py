"""What the laser-odometry front end says of its steps: counts by kind for summary.json and one warning line per
kind of trouble (:class:`~bagtools.odometry.frontend.LaserOdometry` keeps the counts)."""

from __future__ import annotations

from collections import Counter

from bagtools.odometry.options import AMBIGUOUS_WARN_SHARE, FrontEndOptions, StepEvent


def step_warnings(counts: Counter[StepEvent], steps: int, options: FrontEndOptions, topic: str) -> list[str]:
    """One line per kind of trouble among ``steps`` registered scans, with counts (nothing when all went well)."""
    pairs = max(steps - 1, 0)
    out = []
    if counts[StepEvent.FALLBACK] and counts[StepEvent.FALLBACK] >= max(1, 0.02 * pairs):
        out.append(f"{counts[StepEvent.FALLBACK]} of {pairs} scan pairs on {topic} could not be matched (score below "
                   f"{options.min_score:g}) and kept their guess: the trajectory is less reliable there")
    if counts[StepEvent.ODOM_REJECTED]:
        out.append(f"{counts[StepEvent.ODOM_REJECTED]} odometry step(s) contradicted by the scan match beyond the "
                   "odometry's noise (corrupt or slipping samples) were not followed")
    if counts[StepEvent.AMBIGUOUS] >= max(3, AMBIGUOUS_WARN_SHARE * pairs):
        out.append(f"{counts[StepEvent.AMBIGUOUS]} of {pairs} scan pairs on {topic} matched two places almost equally "
                   "well (a repeating scene, or scans that overlap too little): the trajectory may be wrong there; "
                   "wheel odometry or scans closer together would settle it")
    if counts[StepEvent.BEYOND_REACH]:
        out.append(f"{counts[StepEvent.BEYOND_REACH]} scan(s) on {topic} matched only beyond what the robot can do in "
                   "their time step (a wrong stamp, or the robot carried) and were placed there")
    if counts[StepEvent.TOO_FAST]:
        out.append(f"{counts[StepEvent.TOO_FAST]} step(s) faster than {2 * options.max_speed_mps:g} m/s, more than "
                   "the robot can move: check the scans there")
    return out


def step_counts(counts: Counter[StepEvent], steps: int, keyframes: int) -> dict[str, int]:
    """summary.json's counts of the front end's steps."""
    return {"pairs": max(steps - 1, 0), "searched": counts[StepEvent.SEARCHED], "fallbacks": counts[StepEvent.FALLBACK],
            "odometry_rejected": counts[StepEvent.ODOM_REJECTED], "faster_than_robot": counts[StepEvent.TOO_FAST],
            "ambiguous": counts[StepEvent.AMBIGUOUS], "beyond_reach": counts[StepEvent.BEYOND_REACH],
            "revised_by_the_next_scan": counts[StepEvent.REVISED], "keyframes": keyframes}


__all__ = ["step_counts", "step_warnings"]
