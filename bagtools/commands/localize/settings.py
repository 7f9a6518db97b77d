"""The fixed settings of the map localizer (:mod:`bagtools.commands.localize.tracker`): when a hypothesis is committed,
when a scan is poorly matched and the robot lost, the windows searched, how far the motion bounds the robot, and
the states a scan is in. ``docs/commands/localize.md`` ("The tracker, step by step") says where each acts."""

from __future__ import annotations

import math
from enum import StrEnum

#: A hypothesis is committed after matching this many scans (its search's scan included)...
CONFIRM_SCANS = 5
#: ... when its mean score over them beats every other hypothesis' by this much, and is at least FIX_SCORE (a bag
#: from another place matches some walls of any map, at scores of 0.15 to 0.5; the right place scores 0.7 to 0.95
#: on simulated bags and 0.9 on the CSAIL log's map).
CONFIRM_MARGIN = 0.05
FIX_SCORE = 0.5
#: A scan scoring under this share of the typical (median recent) score is poorly matched (a map that lacks
#: part of what the robot sees lowers the score gradually; a kidnap drops it to chance)...
LOST_RATIO = 0.35
#: ... and this many poorly matched scans in a row mean the robot is lost.
LOST_SCANS = 3
#: No score under this is a match, whatever is typical.
MIN_SCORE = 0.15
#: Scores kept for the typical score, and for the usual one (over a longer span: see MapLocalizer._usual).
TYPICAL_SCANS, USUAL_SCANS = 50, 1000
#: The window searched around the prior when the motion is unknown or NDT's result is poor (m, m, rad), and
#: the wide local window searched when that fails too (a fast turn, an odometry glitch) before a scan is a miss.
WINDOW = (0.5, 0.5, 0.4)
LOCAL_WINDOW = (2.0, 2.0, math.pi / 2)
#: A place found after a loss is committed only when it scores this share of the typical score before the loss.
RECOVER_RATIO = 0.8
#: The motion prior's noise floor (m) when the odometry's step is a trusted scan match (``continuous``): the laser
#: odometry is off by a few centimetres over metres on the benchmark logs. Wheel odometry's floor (ODOM_NOISE_M,
#: 5 cm) lets a map that lacks part of what the robot sees pull it along a corridor, match by match.
SCAN_MATCHED_NOISE_M = 0.02
#: Where the odometry went on unbroken since the last good match (the robot was not carried), it is within this
#: many of the prior's standard deviations of where the odometry puts it (they grow with the motion since that match).
BOUND_SIGMAS = 3.0
#: A match fixes the position in every direction when the weaker eigenvalue of NDT's translational Hessian is at
#: least this share of the stronger (0.2 to 0.7 in rooms and crossings on Intel; under 0.02 along its corridors).
CONSTRAINED_RATIO = 0.05
#: NDT's result is not trusted when it moves this far from its prior (m, rad).
NDT_JUMP = (0.25, 0.15)
#: The window search overrules the motion only when it scores this much more than NDT held by the motion.
SWITCH_MARGIN = 0.1
#: NDT held by the motion scoring under this share of the typical score is checked by the window search around
#: it, whose pose is taken when it scores this much more (a drifting motion along a corridor).
CHECK_RATIO, CHECK_MARGIN = 0.9, 0.05
#: The check's window search turns in steps of at most this (rad), a scan of near returns only too (see
#: MapLocalizer._window_search).
MAX_ANGULAR_STEP = 0.05
#: NDT's result is taken unless it scores this much under its start (it diverged).
DIVERGED_SCORE = 0.05
#: A beam passes through a wall when an occupied cell lies on it short of this distance (m) before its return.
THROUGH_TOLERANCE_M = 0.15
#: Beams tested for passing through walls at most this many per scan (spread over the scan), each up to this range (m).
THROUGH_BEAMS, THROUGH_RANGE_M = 120, 10.0
#: A poorly matched scan with less than this share of its returns where the map knows what is there is off the
#: map (a place the map never saw): the motion carries the pose ('unmapped'), and it is no miss.
MAPPED_SHARE = 0.5
#: Cell of the map's normal distributions (m).
NDT_CELL_M = 0.5
#: Hypotheses at most this many; a search that finds none is repeated this many scans later.
MAX_HYPOTHESES = 4
SEARCH_EVERY_SCANS = 5


class TrackState(StrEnum):
    """The tracker's state at a scan (summary.json counts scans by these words)."""

    SEARCHING = "searching"
    CONFIRMING = "confirming"
    AMBIGUOUS = "ambiguous"
    TRACKING = "tracking"
    UNMAPPED = "unmapped"
    LOST = "lost"
