"""Where the robot is in a map it already has, scan by scan, from no initial pose.

:class:`MapLocalizer` takes the scans in recording order (points in the robot base frame, with the base's odometry
pose: the laser odometry, which uses the wheels when the bag has them) and keeps one or more hypotheses of the base's
pose in the map, through four states: **searching** (the global search, :class:`GlobalLocalizer`, places the scan
anywhere), **confirming** (each hypothesis follows the robot until one beats the others), **tracking** (each scan
matched against the map, held by the motion; a window search when NDT is poor; the motion bounds the robot while the
odometry is continuous, and a scan the map does not explain is **unmapped**, carried by the motion) and **lost**.
``docs/commands/localize.md`` ("The tracker, step by step") has each state and the fixed settings
(:mod:`bagtools.commands.localize.settings`) that shape it.

Poses are [x, y, theta] of the base in the map frame (``p_map = R(theta) p_base + [x, y]``); scores are
:meth:`CorrelativeReference.score` on the map's raster, in [0, 1].
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from bagtools.commands.localize.global_search import SEPARATION, GlobalLocalizer
from bagtools.commands.localize.hypotheses import Bound, Event, Fit, Hypothesis, RecentScores
from bagtools.commands.localize.settings import (  # the tracker's fixed settings
    CHECK_MARGIN, CHECK_RATIO, CONFIRM_MARGIN, CONFIRM_SCANS, CONSTRAINED_RATIO, DIVERGED_SCORE, FIX_SCORE,
    LOCAL_WINDOW, LOST_RATIO, LOST_SCANS, MAPPED_SHARE, MAX_ANGULAR_STEP, MAX_HYPOTHESES, MIN_SCORE, NDT_CELL_M,
    NDT_JUMP, RECOVER_RATIO, SCAN_MATCHED_NOISE_M, SEARCH_EVERY_SCANS, SWITCH_MARGIN, THROUGH_BEAMS, THROUGH_RANGE_M,
    THROUGH_TOLERANCE_M, TYPICAL_SCANS, USUAL_SCANS, WINDOW, TrackState,
)
from bagtools.scan_matching import GridMatchResult, NdtReference, match_scans, match_scans_grid
from bagtools.scan_matching.window_search import RASTER_MAX
from bagtools.odometry.motion import (
    ODOM_NOISE_M, PRIOR_WEIGHT_DEFAULT, VELOCITY_SPAN_S, odometry_sd, steady_velocity_sd,
)
from bagtools.transforms import se2_between, se2_compose

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
        self.hypotheses: list[Hypothesis] = []
        self.committed: Hypothesis | None = None
        self.poses: dict[int, np.ndarray] = {}  # scan index -> map pose, once known
        self.matched: set[int] = set()  # the scans of self.poses placed by a good match on the map (not the motion)
        self.scores: dict[int, float] = {}
        self.states: list[str] = []
        self.events: list[Event] = []
        self.typical = RecentScores(TYPICAL_SCANS)
        self.usual = RecentScores(USUAL_SCANS)  # the same scores over a longer span
        self.searches = 0
        self._next_search = 0
        self._initial = None if initial_pose is None else np.asarray(initial_pose, dtype=np.float64)
        self._lost_since: int | None = None
        self._continuous = False
        self._continued: Hypothesis | None = None
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
            return TrackState.UNMAPPED if h.coasting else TrackState.TRACKING
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
        return TrackState.LOST

    def _recent_misses(self, h: Hypothesis, index: int) -> set[int]:
        return set(range(index - h.misses + 1, index + 1))

    def _confirm(self, index: int, stamp_ns: int, points: np.ndarray, odom: np.ndarray | None) -> str:
        if not self.hypotheses:
            if index < self._next_search:
                return TrackState.LOST if self._lost_since is not None else TrackState.SEARCHING
            self._start(index, stamp_ns, points, odom)
            if not self.hypotheses:
                self._next_search = index + SEARCH_EVERY_SCANS
                return TrackState.LOST if self._lost_since is not None else TrackState.SEARCHING
        else:
            for h in self.hypotheses:
                self._follow(h, index, stamp_ns, points, odom)
            self.hypotheses = self._distinct([h for h in self.hypotheses if h.misses < LOST_SCANS])
        if self.hypotheses and self._decide(index, stamp_ns):
            return TrackState.TRACKING
        if self.hypotheses:
            confirmed = max(len(h.scores) for h in self.hypotheses) >= CONFIRM_SCANS
            return TrackState.AMBIGUOUS if confirmed else TrackState.CONFIRMING
        return TrackState.LOST if self._lost_since is not None else TrackState.SEARCHING

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
                h = Hypothesis(pose, index, stamp_ns=stamp_ns)
                h.poses[index] = pose.copy()
                h.matched.add(index)
                h.scores.append(score)
                h.evidence.append(score * (1.0 - self.through_walls(points, pose)))
                h.anchor = None if odom is None else (pose.copy(), odom.copy())
                h.recent.append((stamp_ns, pose.copy()))
                self.hypotheses.append(h)
        if self._continued is not None:  # the lost pose, moved by the motion since, competes with the places
            lost, self._continued = self._continued, None
            h = Hypothesis(lost.pose.copy(), index, stamp_ns=stamp_ns, continued=True, anchor=lost.anchor,
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

    def _distinct(self, hypotheses: list[Hypothesis]) -> list[Hypothesis]:
        """Hypotheses that came to the same place are one (the better scoring one)."""
        kept: list[Hypothesis] = []
        for h in sorted(hypotheses, key=lambda h: -float(np.mean(h.evidence[-CONFIRM_SCANS:]))):
            if all(not _near(h.pose, k.pose, SEPARATION) for k in kept):
                kept.append(h)
        return kept

    # -- matching -------------------------------------------------------------------------------

    def _follow(self, h: Hypothesis, index: int, stamp_ns: int, points: np.ndarray, odom: np.ndarray | None,
                wide: bool = False) -> float:
        """Move hypothesis ``h`` to scan ``index``: its prior from the odometry since its last good match (or its
        recent velocity), matched against the map (``wide``: a wide local search first)."""
        prior, sd = self._prior(h, stamp_ns, odom)
        bounded = h is self.committed and h.unbroken and self._continuous and sd is not None
        off_map = h is self.committed and sd is not None and self._mapped(points, prior) < MAPPED_SHARE
        # Carried by an unbroken motion, the robot is searched for around the prior only every SEARCH_EVERY_SCANS,
        # and only once the scan moved since a search found nothing.
        search = not (bounded and (h.coasting % SEARCH_EVERY_SCANS or not self._moved(h.searched_at, points, odom)))
        bound = Bound(prior, sd, h.loose_m, h.loose_dir) if bounded else None
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

    def _prior(self, h: Hypothesis, stamp_ns: int, odom: np.ndarray | None) -> tuple[np.ndarray, np.ndarray | None]:
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
               wide: bool = False, far: bool = True, bound: Bound | None = None,
               search: bool = True) -> Fit:
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
                held = Fit(prior.copy(), self.fine.score(points, prior), None)
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

    def _checked(self, points: np.ndarray, held: Fit, bound: Bound | None) -> Fit:
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
                sd: np.ndarray | None = None) -> Fit:
        """NDT against the map from ``start`` (a MAP estimate with the Gaussian ``prior``/``sd`` when given): the
        pose, the raster's score there, and the direction the map does not fix the position in (the weak direction
        of NDT's translational Hessian: along a bare corridor), if any; the start is kept when NDT lands clearly
        worse (it diverged)."""
        information = None if prior is None else (prior, 8.0 * len(points) * PRIOR_WEIGHT_DEFAULT * np.diag(1.0 / sd**2))
        result = match_scans(points, self.ndt, initial_pose=start, prior=information)
        refined = np.asarray(result.pose, dtype=np.float64)
        score, before = self.fine.score(points, refined), self.fine.score(points, start)
        if score < before - DIVERGED_SCORE:
            return Fit(start, before, None)
        values, vectors = np.linalg.eigh(0.5 * (result.hessian[:2, :2] + result.hessian[:2, :2].T))
        loose = None if values[1] > 0 and values[0] >= CONSTRAINED_RATIO * values[1] else vectors[:, 0]
        return Fit(refined, score, loose)

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


def _median_range(points: np.ndarray) -> float:
    """The median distance (m) of a scan's returns ((M, 2), base frame) from the base; 0.0 for none."""
    return float(np.median(np.hypot(points[:, 0], points[:, 1]))) if len(points) else 0.0


def _near(a: np.ndarray, b: np.ndarray, tol: tuple[float, float], inclusive: bool = False) -> bool:
    d = se2_between(a, b)
    if inclusive:
        return math.hypot(d[0], d[1]) <= tol[0] and abs(d[2]) <= tol[1]
    return math.hypot(d[0], d[1]) < tol[0] and abs(d[2]) < tol[1]
