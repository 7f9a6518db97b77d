"""Where the robot is in a map it already has, scan by scan, from no initial pose.

:class:`MapLocalizer` takes the scans in recording order (points in the robot
base frame, with the base's odometry pose: the pipeline gives the laser
odometry, which uses the wheels when the bag has them) and keeps one or more
hypotheses of the base's pose in the map:

- **searching**: no hypothesis. The global search (:class:`GlobalLocalizer`)
  places the scan anywhere in the map at any heading; its distinct places
  (a symmetric room gives several) become the hypotheses.
- **confirming**: every hypothesis follows the robot (each scan tracked against
  the map, below); one that stops matching is dropped. The best is committed
  once it has matched ``CONFIRM_SCANS`` scans and beats every other by
  ``CONFIRM_MARGIN`` in mean evidence over them (and scores ``FIX_SCORE``): the
  first fix. A hypothesis' evidence for a scan is its score times the share of
  the scan's beams that do not pass through the map's walls on their way to
  their return: in a room that looks alike turned around, the look-alike place
  puts some walls where the robot saw through. Hypotheses the scans do not tell
  apart by then are *ambiguous*, and a map that repeats itself stays so until
  the robot sees what tells the places apart. The committed hypothesis' earlier
  poses are kept: the trajectory covers the scans since its search.
- **tracking**: each scan matched against the map (not against the previous
  scan), from the last good pose moved by the odometry since (or, without
  odometry, by the velocity of the last half second of good matches): NDT on
  the map's normal distributions held by that prior (matched to where the
  map's walls face its free space), a correlative window search when NDT's
  result is poor or far from the prior, or scores under ``CHECK_RATIO`` of the
  typical score (along a corridor the prior holds NDT wherever a drifting
  motion put it: the window's pose is taken when it scores ``CHECK_MARGIN``
  more, as the robot typically and usually matches and as a fix must), and a
  wide local search (a fast turn, an odometry glitch) when that is poor too. A better
  match where the motion can have taken the robot (``NDT_JUMP``) is taken; one
  anywhere else must beat the motion's by ``SWITCH_MARGIN`` and score as a fix
  must (``FIX_SCORE``, and ``RECOVER_RATIO`` of the typical score): a map that
  merely lacks what the robot sees is no reason to move it.
- **the motion bounds the robot** while the odometry is *continuous* (its maker,
  the laser odometry, matched every scan since the last good match to the ones
  before: the scene went on, so the robot was not carried away). Then it is
  within ``BOUND_SIGMAS`` of the prior's standard deviations (which grow with
  the motion since that match), widened along a corridor the matches since did
  not fix the position along (``CONSTRAINED_RATIO``) by ODOM_NOISE_RATIO of the
  path travelled, and nothing beyond is searched or taken; a
  scan the map does not explain there is no miss: the motion carries the pose
  (**unmapped**), searched around every ``SEARCH_EVERY_SCANS`` scans (once the
  scan moved by a map cell since a search found nothing: standing still, it
  would see the same), until the map is seen again (a correction of more than
  ``WINDOW`` is said: 'corrected').
  This is what holds the robot in a part of the building the map saw only from
  afar (free space, no walls), where a look-alike elsewhere matches better.
- **lost**: otherwise (no odometry's continuity, e.g. a kidnap breaks it), a
  scan scoring under ``LOST_RATIO`` of the typical score after all that,
  ``LOST_SCANS`` times in a row, means the robot is lost: it is counted, said,
  and searched for again, where it was (moved by the motion since, in a wide
  window) competing with the global search's places; a place found after a
  loss must score ``RECOVER_RATIO`` of the typical score before it. A jump the
  motion cannot explain is a loss recovered at once. A poorly matched scan that
  falls mostly where the map knows nothing is off the map (**unmapped**), not
  a miss.

Poses are [x, y, theta] of the base in the map frame (``p_map = R(theta) p_base +
[x, y]``); scores are :meth:`CorrelativeReference.score` on the map's raster, in [0, 1].
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from bagtools.localize.global_search import SEPARATION, GlobalLocalizer
from bagtools.scan_matching import GridMatchResult, NdtReference, match_scans, match_scans_grid
from bagtools.scan_matching.correlative import RASTER_MAX
from bagtools.odometry.motion import (
    ODOM_NOISE_M, ODOM_NOISE_RATIO, PRIOR_WEIGHT_DEFAULT, VELOCITY_SPAN_S, odometry_sd, steady_velocity_sd,
)
from bagtools.transforms import se2_between, se2_compose

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

SEARCHING, CONFIRMING, AMBIGUOUS, TRACKING, UNMAPPED, LOST = (
    "searching", "confirming", "ambiguous", "tracking", "unmapped", "lost")


@dataclass
class _Hypothesis:
    """One place the robot may be: its pose now, the poses and scores of the scans it matched, its misses."""

    pose: np.ndarray
    since: int  # the scan it was born at
    poses: dict[int, np.ndarray] = field(default_factory=dict)
    matched: set[int] = field(default_factory=set)  # the scans it matched well on the map
    scores: list[float] = field(default_factory=list)
    evidence: list[float] = field(default_factory=list)  # score x share of beams not through walls, per scan
    misses: int = 0
    anchor: tuple[np.ndarray, np.ndarray] | None = None  # (map pose, odometry pose) at its last good match
    recent: deque = field(default_factory=lambda: deque(maxlen=50))  # (stamp_ns, map pose) of its good matches
    stamp_ns: int = 0
    continued: bool = False  # where the robot was before it was lost, moved by the motion since
    unbroken: bool = False  # the odometry since its last good match was continuous throughout
    loose_m: float = 0.0  # path (m) from its last match that fixed the position in every direction to its anchor
    loose_dir: np.ndarray | None = None  # the direction (map frame) the matches since did not fix
    coasting: int = 0  # scans in a row carried by the motion (off the map, or a map lacking what it sees)
    searched_at: np.ndarray | None = None  # odometry pose of its last search that found nothing, while carried


class _Fit(NamedTuple):
    """A scan matched on the map: base pose [x, y, theta], raster score, and the direction (unit (2,), map frame)
    along which the map does not fix the position there (a bare corridor's), None where it fixes it in every one."""

    pose: np.ndarray
    score: float
    loose: np.ndarray | None


@dataclass
class Event:
    """Something the localizer did: ``kind`` 'fix' (committed), 'lost', 'recovered' or 'corrected' (the map moved
    the pose by more than WINDOW where the motion was known to be unbroken), at scan ``index`` (stamp ``stamp_ns``)
    and map pose ``pose`` (the last good pose for 'lost')."""

    kind: str
    index: int
    stamp_ns: int
    pose: np.ndarray


class MapLocalizer:
    """Tracks a robot in a map (see the module docstring).

    Args:
        map_points: (N, 2) occupied places of the map, map frame, metres.
        resolution_m: the map's cell (the rasters' and the refinement's).
        initial_pose: [x, y, theta] of the base at the first scan, when known (then no global search at the
            start: the first scan is searched within WINDOW of it).
        sensor_xy: where the laser sits on the base (m): the beams' origin.
        known: map-frame places (N, 2) -> (N,) bool, whether the map knows them (e.g. :meth:`Nav2Map.known`):
            where most of a scan falls on unknown cells, a poor match is the map's gap, not a loss.
        wall_faces: (K, 2) where the map's walls face its free space (:meth:`Nav2Map.wall_faces`), map frame:
            what NDT matches the scans to (the rasters keep ``map_points``); None: ``map_points``.
    """

    def __init__(self, map_points: np.ndarray, resolution_m: float = 0.05,
                 initial_pose: np.ndarray | None = None, sensor_xy: tuple[float, float] = (0.0, 0.0),
                 known: Callable[[np.ndarray], np.ndarray] | None = None,
                 wall_faces: np.ndarray | None = None) -> None:
        self.search = GlobalLocalizer(map_points, fine_m=resolution_m)
        self.fine = self.search.fine
        self.occupied = self.fine.raster == RASTER_MAX  # the cells that hold a map point
        self.sensor_xy = np.asarray(sensor_xy, dtype=np.float64)
        self.known = known
        self.ndt = NdtReference.from_points(map_points if wall_faces is None else wall_faces, cell_size=NDT_CELL_M,
                                            cell_model="widened")
        self.hypotheses: list[_Hypothesis] = []
        self.committed: _Hypothesis | None = None
        self.poses: dict[int, np.ndarray] = {}  # scan index -> map pose, once known
        self.matched: set[int] = set()  # the scans of self.poses placed by a good match on the map (not the motion)
        self.scores: dict[int, float] = {}
        self.states: list[str] = []
        self.events: list[Event] = []
        self.typical = _RecentScores(TYPICAL_SCANS)
        self.usual = _RecentScores(USUAL_SCANS)  # the same scores over a longer span
        self.searches = 0
        self._next_search = 0
        self._initial = None if initial_pose is None else np.asarray(initial_pose, dtype=np.float64)
        self._lost_since: int | None = None
        self._continuous = False
        self._continued: _Hypothesis | None = None
        self._typical_before_loss = 0.0

    # -- one scan -------------------------------------------------------------------------------

    def step(self, index: int, stamp_ns: int, points: np.ndarray, odom: np.ndarray | None,
             continuous: bool = False) -> str:
        """Localize scan ``index`` (points (M, 2) in the base frame; ``odom`` the base's odometry pose
        [x, y, theta] or None); returns its state: 'searching' (no place matches yet), 'confirming' (places
        followed for fewer than CONFIRM_SCANS scans), 'ambiguous' (places the scans do not tell apart yet),
        'tracking', 'unmapped' (the map does not explain the scan: carried by the motion) or 'lost'.
        ``continuous``: the odometry's step into this scan is a scan match its maker trusts (the scene went on:
        the robot was not carried)."""
        odom = None if odom is None else np.asarray(odom, dtype=np.float64)
        self._continuous = continuous and odom is not None
        if self.committed is not None:
            state = self._track_committed(index, stamp_ns, points, odom)
        else:
            state = self._confirm(index, stamp_ns, points, odom)
        self.states.append(state)
        return state

    def _track_committed(self, index: int, stamp_ns: int, points: np.ndarray, odom: np.ndarray | None) -> str:
        h = self.committed
        score = self._follow(h, index, stamp_ns, points, odom)
        if h.misses < LOST_SCANS:
            self.poses[index], self.scores[index] = h.pose.copy(), score
            if index in h.matched:
                self.matched.add(index)
            if h.misses == 0 and not h.coasting:
                self.typical.append(score)
                self.usual.append(score)
            return UNMAPPED if h.coasting else TRACKING
        last_good = max(k for k in h.poses if k not in self._recent_misses(h, index))
        self.events.append(Event("lost", index, stamp_ns, h.poses[last_good]))
        for k in range(index - LOST_SCANS + 1, index + 1):  # the poorly matched scans are not trusted
            self.poses.pop(k, None)
            self.matched.discard(k)
        self.committed, self.hypotheses = None, []
        self._continued = h  # searched again with the global search's places: the robot may not have moved
        self._typical_before_loss = self._typical()
        self._lost_since = index
        self._next_search = index + 1
        return LOST

    def _recent_misses(self, h: _Hypothesis, index: int) -> set[int]:
        return set(range(index - h.misses + 1, index + 1))

    def _confirm(self, index: int, stamp_ns: int, points: np.ndarray, odom: np.ndarray | None) -> str:
        if not self.hypotheses:
            if index < self._next_search:
                return LOST if self._lost_since is not None else SEARCHING
            self._start(index, stamp_ns, points, odom)
            if not self.hypotheses:
                self._next_search = index + SEARCH_EVERY_SCANS
                return LOST if self._lost_since is not None else SEARCHING
        else:
            for h in self.hypotheses:
                self._follow(h, index, stamp_ns, points, odom)
            self.hypotheses = self._distinct([h for h in self.hypotheses if h.misses < LOST_SCANS])
        if self.hypotheses and self._decide(index, stamp_ns):
            return TRACKING
        if self.hypotheses:
            return AMBIGUOUS if max(len(h.scores) for h in self.hypotheses) >= CONFIRM_SCANS else CONFIRMING
        return LOST if self._lost_since is not None else SEARCHING

    def _start(self, index: int, stamp_ns: int, points: np.ndarray, odom: np.ndarray | None) -> None:
        """New hypotheses for scan ``index``: the initial pose's window, or the global search."""
        if self._initial is not None and not self.events:
            found = match_scans_grid(points, self.fine, initial_pose=self._initial, search_range=(1.0, 1.0, 0.5))
            places = [found.pose] if found.ok else []
        else:
            self.searches += 1
            places = [h.pose for h in self.search.search(points, max_hypotheses=MAX_HYPOTHESES)]
        for pose in places:
            pose, score, _ = self._refine(points, np.asarray(pose, dtype=np.float64))
            if score >= MIN_SCORE:
                h = _Hypothesis(pose, index, stamp_ns=stamp_ns)
                h.poses[index] = pose.copy()
                h.matched.add(index)
                h.scores.append(score)
                h.evidence.append(score * (1.0 - self.through_walls(points, pose)))
                h.anchor = None if odom is None else (pose.copy(), odom.copy())
                h.recent.append((stamp_ns, pose.copy()))
                self.hypotheses.append(h)
        if self._continued is not None:  # the lost pose, moved by the motion since, competes with the places
            lost, self._continued = self._continued, None
            h = _Hypothesis(lost.pose.copy(), index, stamp_ns=stamp_ns, continued=True, anchor=lost.anchor,
                            recent=lost.recent)
            self._follow(h, index, stamp_ns, points, odom, wide=True)
            if h.misses == 0:
                self.hypotheses = [h] + [o for o in self.hypotheses if not _near(o.pose, h.pose, SEPARATION)]

    def _decide(self, index: int, stamp_ns: int) -> bool:
        """Commit the best hypothesis if it has held long enough and stands out (see the module docstring)."""
        means = [float(np.mean(h.evidence[-CONFIRM_SCANS:])) for h in self.hypotheses]
        order = np.argsort(means)[::-1]
        best = self.hypotheses[order[0]]
        rivals = [self.hypotheses[i] for i in order[1:] if means[order[0]] - means[i] < CONFIRM_MARGIN]
        if rivals and any(h.continued for h in [best, *rivals]):
            best, rivals = next(h for h in [best, *rivals] if h.continued), []  # alike: the motion decides
        needed = FIX_SCORE if self._lost_since is None else max(FIX_SCORE, RECOVER_RATIO * self._typical_before_loss)
        if len(best.scores) < CONFIRM_SCANS or rivals or np.mean(best.scores[-CONFIRM_SCANS:]) < needed:
            return False
        self.committed, self.hypotheses = best, [best]
        self.typical.extend(best.scores)
        self.usual.extend(best.scores)
        for (k, pose), score in zip(best.poses.items(), best.scores):  # the scans since its search, in hindsight
            self.poses[k], self.scores[k] = pose, score
        self.matched |= best.matched
        kind = "recovered" if self._lost_since is not None else "fix"
        self.events.append(Event(kind, index, stamp_ns, best.pose.copy()))
        self._lost_since = None
        return True

    def _distinct(self, hypotheses: list[_Hypothesis]) -> list[_Hypothesis]:
        """Hypotheses that came to the same place are one (the better scoring one)."""
        kept: list[_Hypothesis] = []
        for h in sorted(hypotheses, key=lambda h: -float(np.mean(h.evidence[-CONFIRM_SCANS:]))):
            if all(not _near(h.pose, k.pose, SEPARATION) for k in kept):
                kept.append(h)
        return kept

    # -- matching -------------------------------------------------------------------------------

    def _follow(self, h: _Hypothesis, index: int, stamp_ns: int, points: np.ndarray, odom: np.ndarray | None,
                wide: bool = False) -> float:
        """Move hypothesis ``h`` to scan ``index``: its prior from the odometry since its last good match (or its
        recent velocity), matched against the map (``wide``: a wide local search first)."""
        prior, sd = self._prior(h, stamp_ns, odom)
        bounded = h is self.committed and h.unbroken and self._continuous and sd is not None
        off_map = h is self.committed and sd is not None and self._mapped(points, prior) < MAPPED_SHARE
        # Carried by an unbroken motion, the robot is searched for around the prior only every SEARCH_EVERY_SCANS,
        # and only once the scan moved since a search found nothing.
        search = not (bounded and (h.coasting % SEARCH_EVERY_SCANS or not self._moved(h.searched_at, points, odom)))
        bound = _Bound(prior, sd, h.loose_m, h.loose_dir) if bounded else None
        pose, score, loose = self._match(points, prior, sd, wide, far=not off_map, bound=bound, search=search)
        jump = se2_between(prior, pose)
        if h is self.committed and score >= self._poor() and (
                abs(jump[0]) > WINDOW[0] or abs(jump[1]) > WINDOW[1] or abs(jump[2]) > WINDOW[2]):
            if bounded:  # the map corrects where the tracking had drifted to (along a corridor, off the map)
                self.events.append(Event("corrected", index, stamp_ns, pose.copy()))
            else:  # where its motion cannot have taken it (a kidnap, an odometry glitch): lost and found at once
                self.events.append(Event("lost", index, stamp_ns, prior.copy()))
                self.events.append(Event("recovered", index, stamp_ns, pose.copy()))
        coasting, h.coasting = h.coasting, 0
        if score >= self._poor() or not bounded:
            h.searched_at = None
        elif search:  # found nothing: not searched again before the scan moves
            h.searched_at = odom.copy()
        if score >= self._poor():
            if loose is None:
                h.loose_m, h.loose_dir = 0.0, None
            elif h is self.committed and odom is not None and h.anchor is not None:
                # along a corridor the map does not fix the position: there it stays as loose as the motion made it
                h.loose_m += float(np.hypot(*se2_between(h.anchor[1], odom)[:2]))
                h.loose_dir = loose
            h.pose, h.misses, h.unbroken = pose, 0, True
            h.matched.add(index)
            h.anchor = None if odom is None else (pose.copy(), odom.copy())
            h.recent.append((stamp_ns, pose.copy()))
        elif off_map or bounded:
            # Off the map, or a map that lacks what the robot sees where its unbroken motion put it (it was not
            # carried away): the motion carries the pose, nothing is missed.
            h.pose, h.coasting, h.unbroken = prior, coasting + 1, bounded
        else:
            h.pose, h.misses = prior, h.misses + 1
        h.poses[index] = h.pose.copy()
        h.scores.append(score)
        if self.committed is not h:  # only while places compete
            h.evidence.append(score * (1.0 - self.through_walls(points, h.pose)))
        h.stamp_ns = stamp_ns
        return score

    def _prior(self, h: _Hypothesis, stamp_ns: int, odom: np.ndarray | None) -> tuple[np.ndarray, np.ndarray | None]:
        """Where ``h`` should be at ``stamp_ns`` and the standard deviations (3,) of that (None: unknown): its
        last good pose moved by the odometry since (noise growing with the motion), else by its velocity over at
        least VELOCITY_SPAN_S of good matches (a scan stamped out of order moves back along it)."""
        if odom is not None and h.anchor is not None:
            pose, at = h.anchor
            step = se2_between(at, odom)
            floor = SCAN_MATCHED_NOISE_M if self._continuous else ODOM_NOISE_M
            return se2_compose(pose, step), odometry_sd(step, floor)
        if len(h.recent) >= 2:
            t1, p1 = h.recent[-1]
            older = [(t, p) for t, p in h.recent if (t1 - t) * 1e-9 >= VELOCITY_SPAN_S]
            if older:
                t0, p0 = older[-1]
                rate = se2_between(p0, p1) / ((t1 - t0) * 1e-9)
                step = rate * ((stamp_ns - t1) * 1e-9)
                return se2_compose(p1, step), steady_velocity_sd(step)
        return h.pose.copy(), None

    def _match(self, points: np.ndarray, prior: np.ndarray, sd: np.ndarray | None,
               wide: bool = False, far: bool = True, bound: _Bound | None = None,
               search: bool = True) -> _Fit:
        """The scan's pose near ``prior`` (standard deviations ``sd`` (3,), None when the motion is unknown) and
        its score: NDT on the map held by the prior (along a corridor the motion decides); a window search
        when the motion is unknown, or when NDT's result is poor or far from the prior; a wide local search
        (LOCAL_WINDOW) when that is poor too and ``far`` (not for a scan off the map), there only for a pose the
        motion cannot explain (scoring :meth:`_far_needed`), or first with ``wide``.
        ``bound``: where the robot can be when the motion went on unbroken since the last good match: nothing
        beyond is searched or taken. Not ``search``: NDT held by the prior alone."""
        held = None
        if sd is not None and not wide:
            held = self._refine(points, prior, prior, sd)
            if _near(prior, held[0], NDT_JUMP, inclusive=True):
                if held.score >= CHECK_RATIO * self._typical():
                    return held
                if held.score >= self._poor():
                    return self._checked(points, held, bound)
            elif held[1] < self._far_needed(sd) or (bound is not None and not bound.holds(held[0])):
                # NDT slid away, and nothing says the motion was wrong
                held = _Fit(prior.copy(), self.fine.score(points, prior), None)
        best = held
        windows = (LOCAL_WINDOW,) if wide else (WINDOW, LOCAL_WINDOW) if far else (WINDOW,)
        if bound is not None:
            reach = tuple(np.minimum(LOCAL_WINDOW, bound.reach()))
            windows = (WINDOW,) if np.all(np.asarray(reach) <= WINDOW) else (WINDOW, reach)
        if not search:
            windows = ()
        for window in windows:
            # A window after the first looks only for what the motion cannot explain (the first covered what it
            # can): its search drops every pose scoring under what such a pose needs, which prunes most of it.
            # Within the bound the first window's pose is taken only when it scores at least poorly (else the
            # motion carries the robot): its search drops every pose under that.
            if window is not windows[0]:
                floor = self._far_needed(sd)
            else:
                floor = self._poor() if bound is not None else 0.0
            found = match_scans_grid(points, self.fine, initial_pose=prior, search_range=window, min_score=floor)
            start = np.asarray(found.pose, dtype=np.float64) if found.ok else prior
            searched = self._refine(points, start, prior if sd is not None and window is WINDOW else None, sd)
            # Where the motion can have taken it (NDT_JUMP), a better match is taken. Anywhere else the scan must
            # clearly say the motion was wrong (not merely a map missing what it sees there), and match as well as
            # the robot typically does; against a known motion, as a fix must (FIX_SCORE).
            explained = window is WINDOW if sd is None else _near(prior, searched[0], NDT_JUMP, inclusive=True)
            if bound is not None and not bound.holds(searched[0]):
                continue
            needed, margin = (self._poor(), 0.0) if explained else (self._far_needed(sd), SWITCH_MARGIN)
            if searched[1] >= needed and (best is None or searched[1] >= best[1] + margin):
                return searched
            if best is None:
                best = searched
        return best

    def _checked(self, points: np.ndarray, held: _Fit, bound: _Bound | None) -> _Fit:
        """NDT held by the motion matched the scan, but worse than the robot typically matches: where a map
        does not fix the position (along a corridor) the prior holds NDT wherever the motion put it, also when
        the motion drifts. The window search around it, refined by the scan alone, is taken when it scores
        CHECK_MARGIN more, as the robot typically and usually matches in this map (CHECK_RATIO) and as a fix must
        (FIX_SCORE): where the map explains the scan, not the best of a poor lot where the map saw the place only
        from afar; within the ``bound`` (or NDT_JUMP of the held pose without one)."""
        found = self._window_search(points, held.pose, WINDOW)
        if not found.ok:
            return held
        searched = self._refine(points, np.asarray(found.pose, dtype=np.float64))
        inside = bound.holds(searched.pose) if bound is not None else _near(held.pose, searched.pose, NDT_JUMP)
        needed = max(held.score + CHECK_MARGIN, CHECK_RATIO * max(self._typical(), self._usual()), FIX_SCORE)
        return searched if inside and searched.score >= needed else held

    def _window_search(self, points: np.ndarray, centre: np.ndarray,
                       window: tuple[float, float, float]) -> GridMatchResult:
        """The check's correlative search of ``window`` around ``centre``, its rotation step the angle that moves
        the scan's median return by one cell (NDT refines what the step leaves): the farthest return's, the
        search's own default, takes several times the headings for nothing. The searches of :meth:`_match` keep
        the default: where the map explains little, the finer step finds what the coarser misses."""
        step = self.fine.resolution_m / max(_median_range(points), self.fine.resolution_m) if len(points) else None
        return match_scans_grid(points, self.fine, initial_pose=centre, search_range=window,
                                angular_resolution_rad=None if step is None else min(step, MAX_ANGULAR_STEP))

    def _moved(self, since: np.ndarray | None, points: np.ndarray, odom: np.ndarray) -> bool:
        """Has the scan (``points``, base frame) moved by a map cell (its median return, odometry pose ``odom``)
        since odometry pose ``since``? True for None."""
        if since is None:
            return True
        moved = se2_between(since, odom)
        return math.hypot(moved[0], moved[1]) + _median_range(points) * abs(moved[2]) >= self.fine.resolution_m

    def _far_needed(self, sd: np.ndarray | None) -> float:
        """The score a pose the motion cannot explain needs (see :meth:`_match`)."""
        return max(self._poor() if sd is None else FIX_SCORE, RECOVER_RATIO * self._typical())

    def _refine(self, points: np.ndarray, start: np.ndarray, prior: np.ndarray | None = None,
                sd: np.ndarray | None = None) -> _Fit:
        """NDT against the map from ``start`` (a MAP estimate with the Gaussian ``prior``/``sd`` when given): the
        pose, the raster's score there, and the direction the map does not fix the position in (the weak direction
        of NDT's translational Hessian: along a bare corridor), if any; the start is kept when NDT lands clearly
        worse (it diverged)."""
        information = None if prior is None else (prior, 8.0 * len(points) * PRIOR_WEIGHT_DEFAULT * np.diag(1.0 / sd**2))
        result = match_scans(points, self.ndt, initial_pose=start, prior=information)
        refined = np.asarray(result.pose, dtype=np.float64)
        score, before = self.fine.score(points, refined), self.fine.score(points, start)
        if score < before - DIVERGED_SCORE:
            return _Fit(start, before, None)
        values, vectors = np.linalg.eigh(0.5 * (result.hessian[:2, :2] + result.hessian[:2, :2].T))
        loose = None if values[1] > 0 and values[0] >= CONSTRAINED_RATIO * values[1] else vectors[:, 0]
        return _Fit(refined, score, loose)

    def through_walls(self, points: np.ndarray, pose: np.ndarray) -> float:
        """The share of the scan's beams (``points`` (M, 2) their returns in the base frame, from ``sensor_xy``)
        that pass through an occupied cell of the map on their way, THROUGH_TOLERANCE_M short of their return,
        at base pose ``pose``; 0.0 for no beam. Up to THROUGH_BEAMS beams, each tested up to THROUGH_RANGE_M."""
        pts = np.asarray(points, dtype=np.float64)
        if len(pts) == 0:
            return 0.0
        pts = pts[np.linspace(0, len(pts) - 1, min(len(pts), THROUGH_BEAMS)).astype(np.intp)]
        c, s = math.cos(pose[2]), math.sin(pose[2])
        R = np.array([[c, -s], [s, c]])
        origin = R @ self.sensor_xy + pose[:2]
        ends = pts @ R.T + pose[:2]
        along = ends - origin
        length = np.hypot(along[:, 0], along[:, 1])
        reach = np.minimum(length - THROUGH_TOLERANCE_M, THROUGH_RANGE_M)
        step = 0.5 * self.fine.resolution_m
        t = np.arange(step, max(float(reach.max()), step) + 1e-9, step)
        with np.errstate(invalid="ignore", divide="ignore"):
            unit = along / length[:, None]
        samples = origin + t[None, :, None] * unit[:, None, :]  # (beams, samples, 2)
        cells = np.floor((samples - self.fine.origin) / self.fine.resolution_m).astype(np.intp)
        nx, ny = self.occupied.shape
        inside = (cells[..., 0] >= 0) & (cells[..., 0] < nx) & (cells[..., 1] >= 0) & (cells[..., 1] < ny)
        hit = np.zeros(inside.shape, dtype=bool)
        hit[inside] = self.occupied[cells[inside][:, 0], cells[inside][:, 1]]
        hit &= t[None, :] <= reach[:, None]
        return float(np.count_nonzero(hit.any(axis=1))) / len(pts)

    def _mapped(self, points: np.ndarray, pose: np.ndarray) -> float:
        """The share of the scan's returns (base frame) that fall, at base pose ``pose``, where the map knows
        what is there (1.0 without a map of known cells)."""
        if self.known is None or len(points) == 0:
            return 1.0
        c, s = math.cos(pose[2]), math.sin(pose[2])
        return float(np.mean(self.known(points @ np.array([[c, s], [-s, c]]) + pose[:2])))

    def _poor(self) -> float:
        """Scores under this are poor matches: LOST_RATIO of the typical score, and never under MIN_SCORE."""
        return max(MIN_SCORE, LOST_RATIO * self._typical())

    def _typical(self) -> float:
        return self.typical.median()

    def _usual(self) -> float:
        """The median score over the last USUAL_SCANS well matched scans: how well this map explains the scans
        where it knows the place (a stretch it saw only from afar lowers the typical score, not this)."""
        return self.usual.median()


class _RecentScores:
    """The last ``n`` scores of well matched scans and their median (0.0 for none), kept until the next score:
    the tracker asks for it several times a scan."""

    def __init__(self, n: int) -> None:
        self.values: deque[float] = deque(maxlen=n)
        self._median: float | None = None

    def append(self, score: float) -> None:
        self.values.append(score)
        self._median = None

    def extend(self, scores: list[float]) -> None:
        self.values.extend(scores)
        self._median = None

    def median(self) -> float:
        if self._median is None:
            self._median = float(np.median(self.values)) if self.values else 0.0
        return self._median


class _Bound(NamedTuple):
    """Where a robot whose motion went on unbroken since its last good match can be: within BOUND_SIGMAS of the
    ``prior`` [x, y, theta] with standard deviations ``sd`` (3,), widened along ``loose_dir`` (unit, map frame: a
    corridor the matches since did not fix the position along) by ODOM_NOISE_RATIO of the ``loose_m`` travelled."""

    prior: np.ndarray
    sd: np.ndarray
    loose_m: float
    loose_dir: np.ndarray | None

    def covariance(self) -> np.ndarray:
        """(2, 2) of the position, map frame (m^2)."""
        P = self.sd[0] ** 2 * np.eye(2)
        if self.loose_dir is not None:
            P = P + (ODOM_NOISE_RATIO * self.loose_m) ** 2 * np.outer(self.loose_dir, self.loose_dir)
        return P

    def holds(self, pose: np.ndarray) -> bool:
        """Is ``pose`` [x, y, theta] within the bound?"""
        d = np.asarray(pose[:2], dtype=np.float64) - self.prior[:2]
        turn = abs(se2_between(self.prior, pose)[2])
        return bool(d @ np.linalg.solve(self.covariance(), d) <= BOUND_SIGMAS**2 and turn <= BOUND_SIGMAS * self.sd[2])

    def reach(self) -> np.ndarray:
        """The search window (x, y, theta half-widths, the prior's frame) that covers the bound."""
        extent = BOUND_SIGMAS * math.sqrt(float(np.linalg.eigvalsh(self.covariance())[1]))
        return np.array([extent, extent, BOUND_SIGMAS * self.sd[2]])


def _median_range(points: np.ndarray) -> float:
    """The median distance (m) of a scan's returns ((M, 2), base frame) from the base; 0.0 for none."""
    return float(np.median(np.hypot(points[:, 0], points[:, 1]))) if len(points) else 0.0


def _near(a: np.ndarray, b: np.ndarray, tol: tuple[float, float], inclusive: bool = False) -> bool:
    d = se2_between(a, b)
    if inclusive:
        return math.hypot(d[0], d[1]) <= tol[0] and abs(d[2]) <= tol[1]
    return math.hypot(d[0], d[1]) < tol[0] and abs(d[2]) < tol[1]
