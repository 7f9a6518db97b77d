"""Laser odometry that holds on real recordings: guesses, gating, a search when a guess cannot be trusted.

:class:`LaserOdometry` registers scans one at a time (the KISS-ICP way). Each scan, in the robot base frame: guesses
(odometry, constant velocity, no motion), NDT from them on the keyframe's submap, a correlative search when no guess
can be trusted, a refinement on finer cells, checks (an ambiguous step's covariance is widened so that a pose graph can
bend there), keyframes. One objective weighs every candidate: the scan's fit less the motion prior's cost
(:mod:`bagtools.odometry.prior`); places that contest it are decided on a finer grid (:mod:`bagtools.odometry.contest`),
and when the one that came second is close on the objective, by the next scan too: the front end goes on along both
for a scan and keeps the better pair of steps. ``docs/commands/ndt-odom.md`` ("How a scan is registered") has each step
and the settings (:mod:`bagtools.odometry.options`). Poses: planar [x, y, theta] (m, m, rad) of the base in the
odometry frame.
"""

from __future__ import annotations

import copy
import math
from collections import Counter, deque
from dataclasses import dataclass

import numpy as np

from bagtools.odometry.contest import close_poses, decide
from bagtools.odometry.motion import (  # the motion model, shared with the localizer
    CV_NOISE_M, CV_NOISE_RAD, CV_NOISE_RATIO, MOTION_MEMORY_S, STAMP_JITTER_S, VELOCITY_SPAN_S,
    odometry_sd, steady_velocity_sd,
)
from bagtools.odometry.options import (  # the method's fixed settings
    AGREE_M, AGREE_RAD, AMBIGUOUS_COVARIANCE, AMBIGUOUS_MARGIN, BASIN_M, BASIN_RAD,
    BEYOND_REACH_GAIN, CONTEST_MARGIN, CONTINUITY_SCORE_RATIO, CV_TURN_PER_M, DEGENERATE_RATIO,
    FINE_SCORE_RESOLUTION_M, FINE_SCORE_WINDOW, MAX_SEARCH_M, MIN_REFINE_CELL_M, MIN_WIDE_POINTS, REFINE_CELL_RATIO,
    REFINE_MAX_M, REFINE_MAX_RAD, SEARCH_SIGMAS, SHORT_STEP_RATIO, SUBMAP_RADIUS_M, WIDE_MAX_PRIOR_COST, WIDE_PEAKS,
    WIDE_PEAK_RATIO, WIDE_SUBMAP_KEYFRAMES, FrontEndOptions, StepEvent, normalized_score,
)
from bagtools.odometry.prior import (
    CV_OUTLIER_COST, OUTLIER_COST, PRIOR_GATE2, Match, MotionPrior, ndt_covariance,
)
from bagtools.odometry.report import step_counts, step_warnings
from bagtools.odometry.steps import FrontEndRun, ScanStep
from bagtools.scan_matching import COVARIANCE_FLOOR, NdtReference, match_scans
from bagtools.scan_matching.correlative import CorrelativeReference, match_scans_grid, match_scans_grid_peaks
from bagtools.scan_matching.grid import voxel_mean
from bagtools.transforms import wrap_to_pi
# single poses in the loop body, tens of calls per scan: without numpy's per-call overhead on 3-vectors
from bagtools.transforms.planar import se2_between_fast as _between
from bagtools.transforms.planar import se2_compose_fast as _compose


@dataclass
class _Keyframe:
    """The reference: a keyframe's pose, and the points of it and the keyframes before it (its submap) in its
    base frame."""

    index: int
    pose: np.ndarray
    points: np.ndarray
    ndt: NdtReference
    first_score: float | None = None
    correlative: CorrelativeReference | None = None
    wide: tuple[NdtReference, CorrelativeReference] | None = None  # the wide search's larger submap, when needed
    fine: NdtReference | None = None  # the submap on the refinement's finer cells, when needed
    fine_field: CorrelativeReference | None = None  # the submap as a fine likelihood field, to decide contests


class LaserOdometry:
    """Registers scans in order (see the module docstring); ``run`` collects the steps."""

    def __init__(self, options: FrontEndOptions | None = None) -> None:
        self.options = options or FrontEndOptions()
        self.run = FrontEndRun()
        self.counts: Counter[StepEvent] = Counter()
        self._keyframe: _Keyframe | None = None
        self._last_odom: np.ndarray | None = None
        self._last_odom_pose = np.zeros(3)  # the pose of the step that had the odometry _last_odom
        self._velocity = np.zeros(3)  # per second, in the base frame
        self._clock_s = 0.0  # the time steps taken so far, summed (s)
        self._recent: deque[tuple[float, np.ndarray]] = deque(maxlen=64)  # (clock, pose) of the matched steps
        self._scores: list[float] = []
        self._steps_s: list[float] = []
        self._after_short_step = False
        self._objectives: deque[float] = deque(maxlen=2)  # the last steps' objectives (score less the prior's cost)
        self._fork: LaserOdometry | None = None  # the other contender of a contested last step, gone on from there
        fine = self.options.cell_size_m * REFINE_CELL_RATIO
        self._refine_cell_m = fine if self.options.refine and fine >= MIN_REFINE_CELL_M else None

    # -- the loop body -------------------------------------------------------------------------

    def register(self, stamp_ns: int, points_base: np.ndarray, odom_pose: np.ndarray | None = None) -> ScanStep:
        """Add one scan: (N,2) valid returns in the base frame, and the odometry pose at its stamp if known. When the
        last step was contested, the scan is registered along both contenders and the better pair of steps kept: the
        step returned before may have been replaced (``run.steps`` holds the kept ones)."""
        points_base = np.asarray(points_base, dtype=np.float64)
        odom = None if odom_pose is None else np.asarray(odom_pose, dtype=np.float64)
        sparse = voxel_mean(points_base, self.options.voxel_m)
        if not self.run.steps:
            return self._record(self._first(stamp_ns, points_base, odom), odom)
        fork, self._fork = self._fork, None
        step = self._record(self._next(stamp_ns, sparse, points_base, odom), odom)
        if fork is not None:  # the last step was contested: the other contender, judged with this scan too
            fork._record(fork._next(stamp_ns, sparse, points_base, odom), odom)
            if sum(fork._objectives) > sum(self._objectives):
                fork.counts[StepEvent.REVISED] += 1
                self.__dict__.update(fork.__dict__)
                return self.run.steps[-1]
        return step

    def _record(self, step: ScanStep, odom: np.ndarray | None) -> ScanStep:
        self.run.steps.append(step)
        if odom is not None:
            self._last_odom, self._last_odom_pose = odom, step.pose
        return step

    def _clone(self) -> LaserOdometry:
        """This front end as it stands, to go on along another contender (the steps and the keyframe shared,
        what a step changes copied)."""
        clone = copy.copy(self)
        clone.run = FrontEndRun(list(self.run.steps))
        clone.counts = Counter(self.counts)
        clone._keyframe = copy.copy(self._keyframe)
        clone._recent = deque(self._recent, maxlen=self._recent.maxlen)
        clone._scores, clone._steps_s = list(self._scores), list(self._steps_s)
        clone._objectives = deque(self._objectives, maxlen=self._objectives.maxlen)
        clone._fork = None
        return clone

    def _first(self, stamp_ns: int, points: np.ndarray, odom: np.ndarray | None) -> ScanStep:
        pose = odom.copy() if odom is not None else np.zeros(3)
        self._recent.append((0.0, pose))
        self._new_keyframe(0, pose, points)
        return ScanStep(stamp_ns, pose, points, -1, np.zeros(3), COVARIANCE_FLOOR.copy(), 1.0, "first", True)

    def _next(self, stamp_ns: int, points: np.ndarray, full: np.ndarray, odom: np.ndarray | None) -> ScanStep:
        """Register a scan: ``points`` (voxel-filtered) are matched; ``full`` is kept and makes keyframes."""
        opts = self.options
        last = self.run.steps[-1]
        late = stamp_ns < last.stamp_ns  # stamped before the scan registered before it, which it came after
        dt = self._typical_step() if late else max((stamp_ns - last.stamp_ns) / 1e9, 1e-3)
        guesses = self._guesses(last.pose, dt, odom)
        kf = self._keyframe
        prior = self._prior(last.pose, dt, guesses, kf)
        matches = self._ndt_from_guesses(points, kf, guesses, prior)
        best = max(matches, key=prior.objective)
        if opts.search and self._needs_search(matches, best, dt, prior):
            self.counts[StepEvent.SEARCHED] += 1
            searched = self._search(points, kf, prior, dt)
            if searched is not None:
                matches.append(searched)
                best = max(matches, key=prior.objective)
            gap = self._gap(dt) and prior.kind != "odometry"
            if (best.score < self._trust_score() or gap) and prior.wide is not None and len(points) >= MIN_WIDE_POINTS:
                # The guess may be what is wrong: search what the robot can have done instead.
                if prior.kind == "odometry":  # rarely wrong: its best alternative on the submap is enough
                    searched = self._search(points, kf, prior.wide, dt)
                    matches += [] if searched is None else [searched]
                else:  # no odometry: the scene must decide, on more of it
                    matches = self._search_wide(points, kf, prior, dt, matches)
                best = max(matches, key=prior.objective)
        beyond = None
        suspect = not late and self._short_step(dt)
        if opts.search and prior.kind != "odometry" and best.score < self._trust_score() and \
                (suspect or self._after_short_step):  # the speed that made the guess came from a suspect stamp
            beyond = self._search_beyond_reach(points, kf, _between(kf.pose, last.pose), best)
        self._steps_s.append(dt)
        self._after_short_step = suspect
        other = None
        if beyond is not None:
            self.counts[StepEvent.BEYOND_REACH] += 1
            best, ambiguous = beyond, False
        else:
            best, ambiguous, other = self._decide(full, kf, matches, best, prior)
        if other is not None and prior.objective(best) - prior.objective(other) < CONTEST_MARGIN:
            # a contest on the objective itself: the other contender goes on too, and the next scan decides
            self._fork = self._clone()
            self._fork._record(self._fork._commit(stamp_ns, full, kf, last, dt, prior, guesses, other, ambiguous,
                                                  None), odom)
        return self._commit(stamp_ns, full, kf, last, dt, prior, guesses, best, ambiguous, beyond)

    def _commit(self, stamp_ns: int, full: np.ndarray, kf: _Keyframe, last: ScanStep, dt: float, prior: MotionPrior,
                guesses: dict[str, np.ndarray], best: Match, ambiguous: bool, beyond: Match | None) -> ScanStep:
        """The step to ``best``: refined, checked, the motion model and the keyframe updated."""
        opts = self.options
        self._objectives.append(prior.objective(best))
        if ambiguous:
            self.counts[StepEvent.AMBIGUOUS] += 1
        if best.score < opts.min_score:
            self.counts[StepEvent.FALLBACK] += 1
            fallback = guesses.get("odom", guesses["constant-velocity"])
            best = Match(_between(kf.pose, fallback), best.score, np.diag([1.0, 1.0, 0.3]), "fallback")
        elif self._refine_cell_m is not None:
            best = self._refine(full, kf, best)
        pose = _compose(kf.pose, best.pose)
        pose[2] = wrap_to_pi(pose[2])
        self._check(last, pose, dt, prior, best)
        self._clock_s += dt
        trusted = (beyond is None and best.source != "fallback" and not ambiguous  # a jump beyond reach: carried?
                   and best.score >= self._trust_score(CONTINUITY_SCORE_RATIO))
        if best.source != "fallback":
            velocity = self._mean_velocity(pose, last.pose)  # never beyond what the robot can do
            velocity[:2] *= min(1.0, opts.max_speed_mps / max(float(np.hypot(velocity[0], velocity[1])), 1e-12))
            velocity[2] = float(np.clip(velocity[2], -opts.max_turn_rate_radps, opts.max_turn_rate_radps))
            self._velocity = velocity
            self._scores.append(best.score)
        keyframe = self._is_new_keyframe(best)
        covariance = best.covariance + AMBIGUOUS_COVARIANCE if ambiguous else best.covariance
        step = ScanStep(stamp_ns, pose, full, kf.index, best.pose, covariance, best.score, best.source, keyframe,
                        ambiguous, trusted)
        if keyframe:
            self._new_keyframe(len(self.run.steps), pose, full)
        return step

    # -- steps of the loop body ----------------------------------------------------------------

    def _guesses(self, last_pose: np.ndarray, dt: float, odom: np.ndarray | None) -> dict[str, np.ndarray]:
        """Absolute pose guesses, the first one to try first."""
        opts = self.options
        cv = self._velocity * min(dt, MOTION_MEMORY_S)
        cv[:2] *= min(1.0, opts.max_speed_mps * dt / max(float(np.hypot(cv[0], cv[1])), 1e-12))
        cv[2] = float(np.clip(cv[2], -opts.max_turn_rate_radps * dt, opts.max_turn_rate_radps * dt))
        guesses: dict[str, np.ndarray] = {}
        if odom is not None and self._last_odom is not None and opts.init in ("auto", "odom"):
            guesses["odom"] = _compose(self._last_odom_pose, _between(self._last_odom, odom))
        guesses["constant-velocity"] = _compose(last_pose, cv)
        guesses["zero"] = last_pose.copy()
        first = opts.init if opts.init in guesses else next(iter(guesses))
        return {first: guesses[first]} | {k: v for k, v in guesses.items() if k != first}

    def _ndt(self, points: np.ndarray, reference: NdtReference, initial: np.ndarray, source: str,
             prior: MotionPrior) -> Match:
        """NDT from ``initial`` with the prior's component there as a MAP term (a corridor keeps the prior's position)."""
        gaussian = prior.component(initial)
        info = gaussian.information(len(points))
        result = match_scans(points, reference, initial_pose=initial, max_iterations=self.options.max_iterations,
                             prior=(gaussian.mean, info))
        score = normalized_score(result.score, result.n_points) if result.score > 0 else 0.0
        return Match(np.asarray(result.pose, dtype=np.float64), score, ndt_covariance(result.hessian, info), source)

    def _ndt_from_guesses(self, points: np.ndarray, kf: _Keyframe, guesses: dict[str, np.ndarray],
                          prior: MotionPrior) -> list[Match]:
        """NDT from the first guess, then from every other guess outside the basins of the results so far."""
        matches: list[Match] = []
        for guess in guesses.values():
            initial = _between(kf.pose, guess)
            if any(close_poses(initial, m.pose, BASIN_M, BASIN_RAD) for m in matches):
                continue
            matches.append(self._ndt(points, kf.ndt, initial, "ndt", prior))
        return matches

    def _prior(self, last_pose: np.ndarray, dt: float, guesses: dict[str, np.ndarray], kf: _Keyframe) -> MotionPrior:
        """Where the scan should be before matching: the odometry's motion (its noise grows with the motion),
        else constant velocity (its uncertainty grows with the time step: the robot may have changed its speed)."""
        opts = self.options
        reach_s = dt + STAMP_JITTER_S
        motion = _between(last_pose, guesses["constant-velocity"])
        sd_xy = CV_NOISE_M + 0.5 * opts.max_accel_mps2 * dt * dt + CV_NOISE_RATIO * float(np.hypot(motion[0], motion[1]))
        sd_theta = CV_NOISE_RAD + 0.5 * opts.max_turn_accel_radps2 * dt * dt + CV_NOISE_RATIO * abs(float(motion[2]))
        last = _between(kf.pose, last_pose)
        origin = last if opts.wheeled else None
        kinematic = MotionPrior(_between(kf.pose, guesses["constant-velocity"]), np.array([sd_xy, sd_xy, sd_theta]),
                           opts.prior_weight, origin=origin,
                           reach=(last, opts.max_speed_mps * reach_s, opts.max_turn_rate_radps * reach_s))
        if "odom" not in guesses and len(self._scores) < 2:  # no speed known yet: anything the robot can do
            return kinematic
        if "odom" not in guesses:
            # A robot mostly keeps its speed: constant velocity as a narrow prior, with what the robot can do
            # (accelerate, stop, start turning) as the rarer alternative.
            return MotionPrior(kinematic.mean, np.minimum(steady_velocity_sd(motion), kinematic.sd),
                          opts.prior_weight, wide=kinematic, outlier_cost=CV_OUTLIER_COST, kind="constant velocity",
                          origin=origin)
        return MotionPrior(_between(kf.pose, guesses["odom"]), odometry_sd(_between(last_pose, guesses["odom"])),
                      opts.prior_weight,
                      wide=kinematic, outlier_cost=OUTLIER_COST, kind="odometry")

    def _decide(self, points: np.ndarray, kf: _Keyframe, matches: list[Match], best: Match,
                prior: MotionPrior) -> tuple[Match, bool, Match | None]:
        """:func:`~bagtools.odometry.contest.decide` on the keyframe's fine field (``points``: the whole scan)."""
        # far-apart scans without odometry: the shortlist's score cannot rank places (with odometry, its prior does)
        margin = math.inf if prior.kind != "odometry" and self._turn_starts() else CONTEST_MARGIN
        return decide(matches, best, prior, margin, lambda pose: self._fine_score(points, kf, pose))

    def _fine_score(self, points: np.ndarray, kf: _Keyframe, pose: np.ndarray) -> float:
        """The best likelihood-field score (in [0, 1]) of ``points`` on the keyframe's submap at
        FINE_SCORE_RESOLUTION_M, within FINE_SCORE_WINDOW of ``pose``."""
        if kf.fine_field is None:
            kf.fine_field = CorrelativeReference.from_points(kf.points, resolution_m=FINE_SCORE_RESOLUTION_M)
        grid = match_scans_grid(points, kf.fine_field, initial_pose=pose, search_range=FINE_SCORE_WINDOW,
                                angular_resolution_rad=self.options.search_angular_resolution_rad)
        return grid.score if grid.ok else 0.0

    def _needs_search(self, matches: list[Match], best: Match, dt: float, prior: MotionPrior) -> bool:
        """The guess cannot be trusted: a poor score, results that disagree, a long gap, or a result the
        prior finds unlikely."""
        if (self._gap(dt) or prior.sd[0] > BASIN_M or prior.sd[2] > BASIN_RAD  # the prior is wider than NDT's basin
                or best.score < self._trust_score() or prior.mahalanobis2(best.pose) > PRIOR_GATE2):
            return True
        rivals = [m for m in matches if m is not best and m.score > 0.8 * best.score]
        return any(not close_poses(m.pose, best.pose, AGREE_M, AGREE_RAD) for m in rivals)

    def _trust_score(self, ratio: float | None = None) -> float:
        """A score to trust: a share (``ratio``, default ``trust_score_ratio``) of the recent typical score (the
        scene decides what is typical), never under ``min_score``."""
        recent = self._scores[-20:]
        typical = float(np.median(recent)) if recent else 0.0
        share = self.options.trust_score_ratio if ratio is None else ratio
        return max(self.options.min_score, share * typical)

    def _search_window(self, prior: MotionPrior, dt: float) -> tuple[float, float, float]:
        """The prior's 3-sigma window (x_m, y_m, theta_rad), within what the robot can do in ``dt``."""
        opts = self.options
        reach_s = dt + STAMP_JITTER_S
        half_xy = float(np.clip(SEARCH_SIGMAS * prior.sd[0], 0.2, min(opts.max_speed_mps * reach_s, MAX_SEARCH_M)))
        half_theta = float(np.clip(SEARCH_SIGMAS * prior.sd[2], 0.1, min(opts.max_turn_rate_radps * reach_s, math.pi)))
        return half_xy, half_xy, half_theta

    def _search(self, points: np.ndarray, kf: _Keyframe, prior: MotionPrior, dt: float) -> Match | None:
        """Grid search over the prior's window, then NDT."""
        opts = self.options
        if kf.correlative is None:
            kf.correlative = CorrelativeReference.from_points(kf.points, resolution_m=opts.search_resolution_m)
        grid = match_scans_grid(points, kf.correlative, initial_pose=prior.mean,
                                search_range=self._search_window(prior, dt),
                                angular_resolution_rad=opts.search_angular_resolution_rad)
        if not grid.ok:
            return None
        return self._ndt(points, kf.ndt, np.asarray(grid.pose, dtype=np.float64), "search", prior)

    def _search_wide(self, points: np.ndarray, kf: _Keyframe, prior: MotionPrior, dt: float,
                     matches: list[Match]) -> list[Match]:
        """Search what the robot can have done (``prior.wide``'s window) against a larger submap: every distinct
        correlative peak and every match so far, refined by NDT on that submap, for the prior to weigh."""
        opts = self.options
        ndt, correlative = self._wide_reference(kf)
        peaks = match_scans_grid_peaks(points, correlative, initial_pose=prior.wide.mean,
                                       search_range=self._search_window(prior.wide, dt),
                                       angular_resolution_rad=opts.search_angular_resolution_rad,
                                       max_peaks=WIDE_PEAKS, min_ratio=WIDE_PEAK_RATIO)
        starts = [(m.pose, m.source) for m in matches] + [(np.asarray(p.pose, dtype=np.float64), "search")
                                                          for p in peaks]
        # The prior's own place at headings across what the robot can turn on the way (CV_TURN_PER_M per metre, two
        # sigmas): a turn whose scan sees new walls scores low on the correlative field, yet NDT from near it finds it.
        n_turns = self._turn_starts()
        starts += [(prior.mean + np.array([0.0, 0.0, 2.0 * BASIN_RAD * k]), "prior")
                   for k in range(-n_turns, n_turns + 1) if k != 0]  # k = 0: the guesses' NDT is in matches
        refined: list[Match] = []
        for initial, source in starts:
            if any(close_poses(initial, m.pose, AGREE_M, AGREE_RAD) for m in refined):
                continue
            if prior.weight * prior.cost(initial) > WIDE_MAX_PRIOR_COST:  # the prior rules it out whatever it scores
                continue
            refined.append(self._ndt(points, ndt, initial, source, prior))
        return refined

    def _turn_starts(self) -> int:
        """How many headings on each side of the prior the wide search starts NDT at (BASIN_RAD x 2 apart): across
        two sigmas of the turn the robot can make over the recent scans' spacing (the median length of the last
        steps, CV_TURN_PER_M per metre). None when the scans are close (dense logs): NDT's basin covers the turn."""
        steps = self.run.steps[-6:]
        lengths = [math.hypot(*_between(a.pose, b.pose)[:2]) for a, b in zip(steps, steps[1:])]
        spacing = float(np.median(lengths)) if lengths else 0.0
        return int(min(2.0 * CV_TURN_PER_M * spacing, math.pi) / (2.0 * BASIN_RAD) + 1e-9)

    def _mean_velocity(self, pose: np.ndarray, last: np.ndarray) -> np.ndarray:
        """The velocity (per second) from the most recent matched step at least VELOCITY_SPAN_S back (or the oldest
        kept) to ``pose`` now: one step's stamps may be off by much of the step, a span's are not. Its direction is
        that of the last step's chord (from ``last``, in its frame), which the next step's repeats when the robot
        keeps turning as it did: the span's chord, turned from half the span's turn to half the last step's."""
        start_s, start = self._recent[0]
        for t, p in reversed(self._recent):
            if self._clock_s - t >= VELOCITY_SPAN_S:
                start_s, start = t, p
                break
        self._recent.append((self._clock_s, pose))
        span = min(max(self._clock_s - start_s, 1e-3), MOTION_MEMORY_S)
        d = _between(start, pose)
        turn = 0.5 * (_between(last, pose)[2] - d[2])
        c, s = math.cos(turn), math.sin(turn)
        return np.array([c * d[0] - s * d[1], s * d[0] + c * d[1], d[2]]) / span

    def _typical_step(self) -> float:
        """The recent typical time step (s): that of a scan whose stamp says nothing of when it was taken (one
        stamped before the scan recorded before it), as the next scan of its laser; STAMP_JITTER_S before any."""
        recent = self._steps_s[-20:]
        return float(np.median(recent)) if recent else STAMP_JITTER_S

    def _gap(self, dt: float) -> bool:
        """A step over ``max_gap_s`` and over 1 / SHORT_STEP_RATIO of the recent typical one (a scan-per-metre log's
        rhythm is no gap): the robot may have done anything meanwhile."""
        return dt > self.options.max_gap_s and SHORT_STEP_RATIO * dt > self._typical_step()

    def _short_step(self, dt: float) -> bool:
        """A time step under SHORT_STEP_RATIO of the recent typical one: its stamp is suspect."""
        return bool(self._steps_s) and dt < SHORT_STEP_RATIO * self._typical_step()

    def _search_beyond_reach(self, points: np.ndarray, kf: _Keyframe, last: np.ndarray, best: Match) -> Match | None:
        """The best match in the largest window around ``last`` (the previous scan's pose in the keyframe's frame:
        no motion, as nothing else is known), on the larger submap, with no reach and no preference (see
        BEYOND_REACH_GAIN); None when none scores well enough to be believed."""
        opts = self.options
        ndt, correlative = self._wide_reference(kf)
        free = MotionPrior(last, np.array([MAX_SEARCH_M, MAX_SEARCH_M, math.pi]), opts.prior_weight)
        peaks = match_scans_grid_peaks(points, correlative, initial_pose=last,
                                       search_range=(MAX_SEARCH_M, MAX_SEARCH_M, math.pi),
                                       angular_resolution_rad=opts.search_angular_resolution_rad,
                                       max_peaks=WIDE_PEAKS, min_ratio=WIDE_PEAK_RATIO)
        found = [self._ndt(points, ndt, np.asarray(p.pose, dtype=np.float64), "search", free) for p in peaks]
        winner = max(found, key=lambda m: m.score, default=None)
        if winner is None or winner.score < max(self._trust_score(), best.score + BEYOND_REACH_GAIN):
            return None
        return winner

    def _wide_reference(self, kf: _Keyframe) -> tuple[NdtReference, CorrelativeReference]:
        """The keyframe's larger submap (built once): its own and up to WIDE_SUBMAP_KEYFRAMES - 1 earlier ones."""
        if kf.wide is None:
            opts = self.options
            points = self._submap_points(kf.index, kf.pose, self.run.steps[kf.index].points_base,
                                         WIDE_SUBMAP_KEYFRAMES)
            kf.wide = (NdtReference.from_points(points, opts.cell_size_m, opts.cell_model),
                       CorrelativeReference.from_points(points, resolution_m=opts.search_resolution_m))
        return kf.wide

    def _refine(self, points: np.ndarray, kf: _Keyframe, best: Match) -> Match:
        """``best`` refined by NDT on the keyframe's submap with the finer cells (``points``: the whole scan)."""
        if kf.fine is None:
            kf.fine = NdtReference.from_points(kf.points, self._refine_cell_m, self.options.cell_model)
        result = match_scans(points, kf.fine, initial_pose=best.pose, max_iterations=self.options.max_iterations)
        pose = np.asarray(result.pose, dtype=np.float64)
        if result.score <= 0 or not close_poses(best.pose, pose, REFINE_MAX_M, REFINE_MAX_RAD):
            return best
        pose[:2] = best.pose[:2] + _constrained(pose[:2] - best.pose[:2], np.asarray(result.hessian)[:2, :2])
        return Match(pose, best.score, best.covariance, best.source)

    def _check(self, last: ScanStep, pose: np.ndarray, dt: float, prior: MotionPrior, best: Match) -> None:
        """Count odometry the match contradicts beyond its noise, and steps faster than the robot can move."""
        step = _between(last.pose, pose)
        if prior.kind == "odometry" and best.source != "fallback" and prior.mahalanobis2(best.pose) > PRIOR_GATE2:
            self.counts[StepEvent.ODOM_REJECTED] += 1
        if np.hypot(step[0], step[1]) > 2.0 * self.options.max_speed_mps * dt + 0.1:
            self.counts[StepEvent.TOO_FAST] += 1

    def _is_new_keyframe(self, match: Match) -> bool:
        opts = self.options
        kf = self._keyframe
        if opts.reference == "previous" or match.source == "fallback":
            return True
        if kf.first_score is None:
            kf.first_score = match.score
        return bool(np.hypot(match.pose[0], match.pose[1]) >= opts.keyframe_distance_m
                    or abs(match.pose[2]) >= opts.keyframe_angle_rad
                    or match.score < opts.keyframe_score_ratio * kf.first_score)

    def _new_keyframe(self, index: int, pose: np.ndarray, points: np.ndarray) -> None:
        """Make scan ``index`` the reference, with the last ``submap_keyframes`` keyframes' points moved into it."""
        opts = self.options
        submap = self._submap_points(index, pose, points, opts.submap_keyframes)
        self._keyframe = _Keyframe(index, pose.copy(), submap,
                                   NdtReference.from_points(submap, opts.cell_size_m, opts.cell_model))

    def _submap_points(self, index: int, pose: np.ndarray, points: np.ndarray, n_keyframes: int) -> np.ndarray:
        """``points`` (scan ``index``, at ``pose``) and those of the ``n_keyframes`` - 1 keyframes before it
        within SUBMAP_RADIUS_M, in its base frame."""
        parts = [points]
        earlier: list[int] = []  # the keyframes before it, latest first (a walk back, not a scan of every step)
        k = min(index, len(self.run.steps)) - 1
        while k >= 0 and len(earlier) < n_keyframes - 1:
            if self.run.steps[k].keyframe:
                earlier.append(k)
            k -= 1
        for k in earlier:
            older = self.run.steps[k]
            rel = _between(pose, older.pose)
            if np.hypot(rel[0], rel[1]) > SUBMAP_RADIUS_M:
                break
            c, s = np.cos(rel[2]), np.sin(rel[2])
            parts.append(older.points_base @ np.array([[c, s], [-s, c]]) + rel[:2])
        return np.concatenate(parts) if len(parts) > 1 else points

    # -- reporting (:mod:`bagtools.odometry.report`) ---------------------------------------------

    def warnings(self, topic: str = "the scans") -> list[str]:
        """One line per kind of trouble, with counts (nothing when all went well)."""
        return step_warnings(self.counts, len(self.run.steps), self.options, topic)

    def summary_counts(self) -> dict[str, int]:
        return step_counts(self.counts, len(self.run.steps), len(self.run.keyframe_indexes))


def _constrained(move: np.ndarray, hessian: np.ndarray) -> np.ndarray:
    """``move`` (2,) without its component along a direction ``hessian`` (2,2, of a cost in that space) barely
    constrains (eigenvalue under DEGENERATE_RATIO of the largest)."""
    values, vectors = np.linalg.eigh(0.5 * (hessian + hessian.T))
    if values[1] <= 0:
        return np.zeros_like(move)
    weak = vectors[:, 0]
    return move - weak * float(weak @ move) if values[0] < DEGENERATE_RATIO * values[1] else move

