"""The motion model the laser odometry and the localizer share: how far a robot's pose can be from a prediction.

A step is predicted by the wheel odometry's motion since the last scan, or, without odometry, by constant velocity.
Each prediction comes with standard deviations (m, m, rad) that grow with the motion: a floor plus a share of the
distance and of the turn. The front end (:mod:`bagtools.odometry.frontend`) and the localizer
(:mod:`bagtools.commands.localize.tracker`) take them from here, so that a change to the model changes both.

Poses and motions are planar [x, y, theta] (m, m, rad).
"""

from __future__ import annotations


import numpy as np

#: Odometry's noise per step: a floor plus a share of the motion (sd, m and rad).
ODOM_NOISE_M, ODOM_NOISE_RATIO = 0.05, 0.1
ODOM_NOISE_RAD, ODOM_TURN_NOISE_RATIO = 0.05, 0.3
#: Constant velocity's uncertainty: a floor, what acceleration can change in the step, and a share of the motion.
CV_NOISE_M, CV_NOISE_RAD, CV_NOISE_RATIO = 0.05, 0.03, 0.2
#: Without odometry: constant velocity's narrow spread (m, rad, share of the motion): a robot mostly keeps its speed.
CV_STEADY_M, CV_STEADY_RAD, CV_STEADY_RATIO = 0.1, 0.1, 0.2
#: A candidate's score loses this much per unit of squared Mahalanobis distance from the prior: where the
#: scene cannot tell poses apart (a corridor), the prior decides; where it can, the score does.
PRIOR_WEIGHT_DEFAULT = 0.01
#: A scan's stamp may be off by this much (s): what the robot can do in a step (its reach, the search window) is
#: reckoned over the time step plus this, so that a late or early stamp (a driver's, or a log resampled from
#: another clock) does not rule out the true motion.
STAMP_JITTER_S = 0.25
#: Constant velocity is the motion over at least this much time (s): over one step, a stamp off by STAMP_JITTER_S
#: would make it anything.
VELOCITY_SPAN_S = 0.5
#: A robot keeps a speed for about this long (s): over a longer step it may have stopped, waited and gone on (a log
#: that writes a scan per metre, a pause), so the motion of such a step is taken as MOTION_MEMORY_S of travel at the
#: recent speed, and a step of d metres over a longer span as d metres in MOTION_MEMORY_S (a speed, not an average
#: over the waits).
MOTION_MEMORY_S = 2.0


def odometry_sd(motion: np.ndarray, floor_m: float = ODOM_NOISE_M) -> np.ndarray:
    """Standard deviations (3,) (m, m, rad) of a pose predicted by an odometry ``motion`` [dx, dy, dtheta]: the
    ``floor_m`` (ODOM_NOISE_M: the wheels alone) plus ODOM_NOISE_RATIO of the distance, ODOM_NOISE_RAD plus
    ODOM_TURN_NOISE_RATIO of the turn."""
    grow = ODOM_NOISE_RATIO * float(np.hypot(motion[0], motion[1]))
    return np.array([floor_m + grow, floor_m + grow, ODOM_NOISE_RAD + ODOM_TURN_NOISE_RATIO * abs(float(motion[2]))])


def steady_velocity_sd(motion: np.ndarray) -> np.ndarray:
    """Standard deviations (3,) (m, m, rad) of a pose predicted by constant velocity (``motion`` [dx, dy, dtheta]
    over the step) when the robot keeps its speed: CV_STEADY_M/_RAD plus CV_STEADY_RATIO of the motion."""
    grow = CV_STEADY_RATIO * float(np.hypot(motion[0], motion[1]))
    return np.array([CV_STEADY_M + grow, CV_STEADY_M + grow, CV_STEADY_RAD + CV_STEADY_RATIO * abs(float(motion[2]))])


__all__ = [
    "CV_NOISE_M", "CV_NOISE_RAD", "CV_NOISE_RATIO", "CV_STEADY_M", "CV_STEADY_RAD", "CV_STEADY_RATIO",
    "MOTION_MEMORY_S", "ODOM_NOISE_M", "ODOM_NOISE_RAD", "ODOM_NOISE_RATIO", "ODOM_TURN_NOISE_RATIO",
    "PRIOR_WEIGHT_DEFAULT", "STAMP_JITTER_S", "VELOCITY_SPAN_S", "odometry_sd", "steady_velocity_sd",
]
