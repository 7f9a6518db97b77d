"""The front end on scans far apart, without odometry, with odometry that slips, and on the real CSAIL log."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from bagtools.commands.ndt_odom import NdtOdomOptions, run_front_end
from bagtools.odometry import FrontEndOptions, LaserOdometry
from bagtools.odometry.frontend import _constrained
from bagtools.trajectory import rpe_frames
from bagtools.transforms import se2_between, se2_compose, tform2pose
from tests.conftest import FIXTURES


@pytest.fixture(scope="module")
def lap():
    """The 20 s fixture lap: each scan's points in the base frame and its true base pose (map)."""
    result = run_front_end(FIXTURES / "sim_lap_cloud_20s")
    truth = result.ground_truth
    at = np.searchsorted(truth.stamps_ns, result.front_end.stamps_ns())
    return result.front_end.steps, tform2pose(truth.poses[at])


def step_errors(poses: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """(N-1,3) error of each step: (true step)^-1 (estimated step)."""
    return se2_between(se2_between(truth[:-1], truth[1:]), se2_between(poses[:-1], poses[1:]))


def register(steps, truth, keep, odom=None, **options) -> LaserOdometry:
    front = LaserOdometry(FrontEndOptions(cell_size_m=0.5, voxel_m=0.1, **options))
    for k in keep:
        front.register(steps[k].stamp_ns, steps[k].points_base, None if odom is None else odom[k])
    return front


def test_scans_far_apart_without_odometry_are_found_by_the_search(lap) -> None:
    """One scan a second (up to 0.26 m and 0.5 rad apart), no odometry: the grid search finds each motion."""
    steps, truth = lap
    keep = np.arange(0, len(steps), 5)
    front = register(steps, truth, keep)
    err = step_errors(front.run.poses(), truth[keep])
    assert front.counts["searched"] > 0 and front.counts["fallback"] == 0
    assert np.hypot(err[:, 0], err[:, 1]).max() < 0.03 and np.abs(err[:, 2]).max() < np.radians(1.0)
    assert front.warnings() == []


def test_a_scan_stamped_before_the_scan_before_it_is_the_next_of_its_laser(lap) -> None:
    """Scans 1 s apart, no odometry, every fifth stamped 1.5 s before the scan registered before it (as the Intel
    log stamps 631 scans): its stamp says nothing of when it was taken, so it is registered as the next scan, one
    typical step later: no search beyond what the robot can do (where a look-alike may score better), and every
    step right."""
    steps, truth = lap
    keep = np.arange(0, len(steps), 5)
    stamps = np.array([steps[k].stamp_ns for k in keep])
    stamps[5::5] -= 2_500_000_000
    assert (np.diff(stamps) < 0).sum() == len(stamps[5::5])
    front = LaserOdometry(FrontEndOptions(cell_size_m=0.5, voxel_m=0.1))
    for k, stamp in zip(keep, stamps):
        front.register(int(stamp), steps[k].points_base, None)
    err = step_errors(front.run.poses(), truth[keep])
    assert front.counts["beyond_reach"] == 0, front.counts
    assert np.hypot(err[:, 0], err[:, 1]).max() < 0.03 and np.abs(err[:, 2]).max() < np.radians(1.0)


def test_constant_velocity_holds_when_every_stamp_is_off(lap) -> None:
    """No odometry, stamps off by +-40 % of the time step in turn (a log resampled from another clock): one step's
    motion over its own time step says 0.4x or 3x the speed; the motion over half a second says it within the
    jitter's share of that span."""
    steps, truth = lap
    true_stamps = np.array([s.stamp_ns for s in steps])
    step_ns = int(np.median(np.diff(true_stamps)))
    stamps = true_stamps + np.where(np.arange(len(steps)) % 2 == 0, 1, -1) * int(0.4 * step_ns)
    front = LaserOdometry(FrontEndOptions(cell_size_m=0.5, voxel_m=0.1))
    errors = []
    for k, stamp in enumerate(stamps):
        front.register(int(stamp), steps[k].points_base, None)
        if k >= 5:  # the true speed over the last true second, at this scan
            back = k - 5
            true_speed = np.hypot(*se2_between(truth[back], truth[k])[:2]) / ((true_stamps[k] - true_stamps[back]) / 1e9)
            errors.append(abs(np.hypot(*front._velocity[:2]) - true_speed))
    assert np.median(errors) < 0.03 and np.percentile(errors, 90) < 0.1, (np.median(errors), np.percentile(errors, 90))


@pytest.mark.parametrize("enabled", [True, False])
def test_a_suspect_stamp_is_searched_beyond_reach(lap, monkeypatch, enabled: bool) -> None:
    """Scans 2 s apart (up to 0.5 m and 1 rad), no odometry, one stamped 20 ms after the scan before it (a log
    resampled from another clock): within what the robot can do in 20 ms nothing matches; the search beyond reach
    places the scan right, counts and says it. Without it (enabled=False) the step is wrong."""
    import bagtools.odometry.frontend as frontend

    if not enabled:
        monkeypatch.setattr(frontend, "SHORT_STEP_RATIO", 0.0)
    steps, truth = lap
    keep = np.arange(0, len(steps), 10)
    stamps = np.array([steps[k].stamp_ns for k in keep])
    bad = 6
    stamps[bad] = stamps[bad - 1] + 20_000_000
    front = LaserOdometry(FrontEndOptions(cell_size_m=0.5, voxel_m=0.1))
    for k, stamp in zip(keep, stamps):
        front.register(int(stamp), steps[k].points_base, None)
    err = step_errors(front.run.poses(), truth[keep])
    moved = se2_between(truth[keep[bad - 1]], truth[keep[bad]])
    assert np.hypot(moved[0], moved[1]) > 0.4 or abs(moved[2]) > 0.6, moved  # beyond 20 ms (+ jitter) of reach
    worst = max(np.hypot(err[:, 0], err[:, 1]).max(), np.abs(err[:, 2]).max())
    if enabled:
        assert front.counts["beyond_reach"] >= 1 and worst < 0.03, (front.counts, worst)
        assert any("beyond what the robot can do" in w for w in front.warnings()), front.warnings()
    else:
        assert front.counts["beyond_reach"] == 0 and worst > 0.1, worst


def test_odometry_that_slips_is_rejected_and_said(lap) -> None:
    steps, truth = lap
    keep = np.arange(len(steps))
    odom = truth.copy()
    for k in (30, 60, 61, 90):  # the wheels slip: a step of 0.3 m and 0.4 rad that never happened
        odom[k:] = se2_compose(odom[k:], [0.3, 0.0, 0.4])
    front = register(steps, truth, keep, odom)
    err = step_errors(front.run.poses(), truth)
    assert front.counts["odometry_rejected"] == 4 and front.counts["fallback"] == 0
    assert np.hypot(err[:, 0], err[:, 1]).max() < 0.03
    assert any("4 odometry step(s) contradicted" in w for w in front.warnings())


def test_good_odometry_needs_no_search_and_raises_nothing(lap) -> None:
    steps, truth = lap
    front = register(steps, truth, np.arange(len(steps)), truth)
    assert front.counts["searched"] <= 2 and front.counts["odometry_rejected"] == 0 and front.warnings() == []


@pytest.fixture(scope="module")
def csail(request):
    real = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "real"
    if not (real / "csail_odom").is_dir():
        pytest.skip(f"real bags not available: {real}")
    return real


def per_scan(result) -> tuple[np.ndarray, np.ndarray]:
    return rpe_frames(result.ground_truth, result.trajectory, delta=1)


def test_csail_with_odometry(csail: Path) -> None:
    """Issue targets: per step at most 3 cm and 1 degree (asserted loosely), few steps over 0.2 m, far better than
    the wheels."""
    result = run_front_end(csail / "csail_odom")
    trans, rot = per_scan(result)
    assert trans.mean() < 0.032 and rot.mean() < 1.0, (trans.mean(), rot.mean())
    # Over 0.2 m: steps 364 and 399, where GMapping's reference itself is off (see bench/RESULTS.md)
    assert np.count_nonzero(trans > 0.2) <= 3
    s = result.summary
    assert s["fallbacks"] <= 4 and s["errors_ndt"]["ape_translation_m"]["rmse"] < 0.25 * \
        s["errors_odometry"]["ape_translation_m"]["rmse"]


def test_csail_without_odometry_does_not_diverge(csail_scans_run) -> None:
    result = csail_scans_run
    trans, rot = per_scan(result)
    s = result.summary
    assert s["fallbacks"] <= 4  # at most 1% of 405 pairs
    # Issue targets: per step at most 3 cm and 1 degree (asserted loosely); the sharp turns after a gap whose mirror
    # image matches as well (steps 52-53) are found by the wide search on a larger submap.
    assert trans.mean() < 0.032 and rot.mean() < 1.0, (trans.mean(), rot.mean())
    assert np.count_nonzero(trans > 0.2) <= 3


def test_a_wheeled_robot_does_not_step_sideways() -> None:
    """The kinematic prior's arc term: a step along the arc costs nothing sideways, a sideways jump costs much."""
    from bagtools.odometry.prior import MotionPrior

    prior = MotionPrior(np.array([1.0, 0.0, 0.0]), np.array([1.0, 1.0, 1.0]), origin=np.zeros(3))
    turn = 0.6
    on_arc = np.array([np.cos(turn / 2), np.sin(turn / 2), turn])  # 1 m along an arc turning 0.6 rad
    sideways = np.array([1.0, -1.0, 0.0])
    plain = MotionPrior(prior.mean, prior.sd)
    assert prior.mahalanobis2(on_arc) - plain.mahalanobis2(on_arc) < 1e-9
    assert prior.mahalanobis2(sideways) - plain.mahalanobis2(sideways) > 25.0


def test_a_step_beyond_what_the_robot_can_do_costs_steeply() -> None:
    """The kinematic prior's reach: within max speed x time nothing is added; 0.15 m or 0.15 rad beyond, 9 units."""
    from bagtools.odometry.prior import REACH_SD_M, REACH_SD_RAD, MotionPrior

    start = np.array([0.5, 0.2, 0.3])
    prior = MotionPrior(start, np.array([10.0, 10.0, 10.0]), reach=(start, 2.0, 1.0))
    plain = MotionPrior(prior.mean, prior.sd)

    def ahead(d: float, turn: float) -> np.ndarray:
        return np.array([start[0] + d * np.cos(start[2]), start[1] + d * np.sin(start[2]), start[2] + turn])

    for within in (ahead(1.99, 0.0), ahead(0.0, -0.99), ahead(1.5, 0.9)):
        assert prior.mahalanobis2(within) == pytest.approx(plain.mahalanobis2(within))
    assert prior.mahalanobis2(ahead(2.15, 0.0)) - plain.mahalanobis2(ahead(2.15, 0.0)) == pytest.approx(
        (0.15 / REACH_SD_M) ** 2)
    assert prior.mahalanobis2(ahead(1.0, -1.15)) - plain.mahalanobis2(ahead(1.0, -1.15)) == pytest.approx(
        (0.15 / REACH_SD_RAD) ** 2)


def test_large_cells_are_refined_on_finer_cells_small_ones_are_not() -> None:
    assert LaserOdometry(FrontEndOptions(cell_size_m=1.0))._refine_cell_m == pytest.approx(1.0 / np.sqrt(2.0))
    assert LaserOdometry(FrontEndOptions(cell_size_m=0.5))._refine_cell_m is None  # 0.35 m cells: too few points
    assert LaserOdometry(FrontEndOptions(cell_size_m=1.0, refine=False))._refine_cell_m is None


def test_the_refinement_keeps_the_lap_accurate(lap) -> None:
    """Large cells on the lap, with and without the finer-cell refinement: it holds the steps within 2 cm."""
    steps, truth = lap
    keep = np.arange(len(steps))
    errors = {}
    for refine in (False, True):
        front = LaserOdometry(FrontEndOptions(cell_size_m=1.0, voxel_m=0.2, refine=refine))
        for k in keep:
            front.register(steps[k].stamp_ns, steps[k].points_base, None)
        err = step_errors(front.run.poses(), truth)
        errors[refine] = np.hypot(err[:, 0], err[:, 1])
        assert errors[refine].max() < 0.02 and np.abs(err[:, 2]).max() < np.radians(1.0), (refine, errors[refine].max())
    assert errors[True].mean() < 1.2 * errors[False].mean(), (errors[True].mean(), errors[False].mean())


@pytest.mark.parametrize("angle", [0.0, 0.7, 2.0])
def test_the_refinement_keeps_out_of_a_direction_its_cost_does_not_constrain(angle: float) -> None:
    """A corridor along ``angle``: the fine cost's curvature along it is 1 % of that across it, and a move along it
    is dropped; with a curvature of 10 % (doors, a junction) the move is kept whole."""
    along, across = np.array([np.cos(angle), np.sin(angle)]), np.array([-np.sin(angle), np.cos(angle)])
    move = 0.1 * along + 0.02 * across
    corridor = 100.0 * np.outer(across, across) + 1.0 * np.outer(along, along)
    assert np.allclose(_constrained(move, corridor), 0.02 * across)
    room = 100.0 * np.outer(across, across) + 10.0 * np.outer(along, along)
    assert np.allclose(_constrained(move, room), move)
    assert np.allclose(_constrained(move, np.zeros((2, 2))), 0.0)  # no curvature at all: no move is taken


@pytest.mark.parametrize("first", [1, 2, 5, 13])
def test_csail_without_odometry_holds_from_other_first_scans(csail_scans_run, csail_restarted, first: int) -> None:
    """The same log started a few scans later (other speeds and keyframes at the sharp turns of scans 52-66, where
    a mirror image or a half-seen room matches nearly as well on the 1 m NDT cells): no step goes wrong by half a
    metre or 30 degrees, and the turn into scan 67 (taken 27 degrees wrong from these starts before the fine grid
    decided such contests) is within 5 degrees."""
    truth = csail_scans_run.ground_truth
    run = csail_restarted(first)
    at = np.searchsorted(truth.stamps_ns, run.stamps_ns())
    err = step_errors(run.poses(), tform2pose(truth.poses[at]))
    wrong = np.flatnonzero((np.hypot(err[:, 0], err[:, 1]) > 0.5) | (np.abs(err[:, 2]) > np.radians(30.0))) + first
    assert wrong.size == 0, wrong
    into_67 = 67 - first - 1  # err[i]: the step from scan first + i to scan first + i + 1
    assert abs(np.degrees(err[into_67, 2])) < 5.0, np.degrees(err[into_67])


def test_csail_half_the_scans_without_odometry_warns_of_ambiguous_matches(csail_scans_run) -> None:
    """Every other scan (2 m and up to 130 degrees apart, with a 180-degree laser): many steps could be either of
    two places, and the run says so; at the log's own rate it does not."""
    from bagtools.odometry.options import cell_size_for

    assert not any("almost equally well" in w for w in csail_scans_run.summary["warnings"])
    assert csail_scans_run.summary["ambiguous"] <= 8
    steps = csail_scans_run.front_end.steps[::2]
    front = LaserOdometry(NdtOdomOptions(use_odometry=False).front_end(cell_size_for([s.points_base for s in steps])))
    for step in steps:
        front.register(step.stamp_ns, step.points_base, None)
    counts = front.summary_counts()
    assert counts["ambiguous"] >= 0.05 * counts["pairs"], counts
    assert any(f"{counts['ambiguous']} of {counts['pairs']} scan pairs on the scans matched two places almost equally "
               "well" in w for w in front.warnings()), front.warnings()


def test_a_wait_of_minutes_predicts_seconds_of_travel_not_minutes() -> None:
    """Constant velocity over a 112 s step (a log that writes a scan per metre, a pause): MOTION_MEMORY_S of travel
    at the recent speed, not 112 s of it (FHW went 63 m the wrong way); a dense log's 0.2 s step is unchanged."""
    from bagtools.odometry.frontend import MOTION_MEMORY_S

    odometry = LaserOdometry()
    odometry._velocity = np.array([0.5, 0.0, 0.1])
    long = odometry._guesses(np.zeros(3), 112.0, None)["constant-velocity"]
    assert np.allclose(long, [0.5 * MOTION_MEMORY_S, 0.0, 0.1 * MOTION_MEMORY_S])
    short = odometry._guesses(np.zeros(3), 0.2, None)["constant-velocity"]
    assert np.allclose(short, [0.1, 0.0, 0.02])


def test_turns_are_searched_only_where_scans_lie_far_apart() -> None:
    """Scans a metre apart (a robot turns into a side corridor within one): the wide search starts at several
    headings; scans 10 cm apart (every dense log): none, NDT's basin covers the turn."""
    from bagtools.odometry.steps import ScanStep

    def spaced(step_m: float) -> LaserOdometry:
        odometry = LaserOdometry()
        for k in range(6):
            odometry.run.steps.append(ScanStep(k, np.array([k * step_m, 0.0, 0.0]), np.zeros((0, 2)), k - 1,
                                               np.zeros(3), np.eye(3), 1.0, "ndt", True))
        return odometry

    assert spaced(1.0)._turn_starts() == 3  # +-0.2, 0.4, 0.6 rad: two sigmas of 0.3 rad per metre
    assert spaced(0.1)._turn_starts() == 0


def test_a_gap_is_measured_against_the_logs_own_rhythm() -> None:
    """A step is a gap (the robot may have done anything: the wide search) when it is over ``max_gap_s`` and over
    four times the recent typical step: a dense log's 2 s pause is one, a scan-per-metre log's 6 s step is not, its
    25 s pause is."""
    odometry = LaserOdometry()
    assert odometry._gap(2.0) and not odometry._gap(1.0)  # no steps yet: max_gap_s (1.5 s)
    odometry._steps_s = [0.1] * 20
    assert odometry._gap(2.0) and not odometry._gap(1.0)
    odometry._steps_s = [5.0] * 20
    assert not odometry._gap(6.0) and odometry._gap(25.0)


def test_scans_seconds_apart_are_not_searched_widely_at_every_step(lap, monkeypatch) -> None:
    """Scans 5 s apart by their stamps (a log that writes a scan per metre): steps the motion model and the scene
    agree on are not searched over what the robot can do in 5 s; every step is right."""
    steps, truth = lap
    keep = np.arange(0, len(steps), 5)
    wide = []
    original = LaserOdometry._search_wide
    monkeypatch.setattr(LaserOdometry, "_search_wide", lambda self, *a: wide.append(1) or original(self, *a))
    front = LaserOdometry(FrontEndOptions(cell_size_m=0.5, voxel_m=0.1))
    for k in keep:
        front.register(int(steps[0].stamp_ns + 5 * (steps[k].stamp_ns - steps[0].stamp_ns)), steps[k].points_base)
    err = step_errors(front.run.poses(), truth[keep])
    assert np.hypot(err[:, 0], err[:, 1]).max() < 0.03 and np.abs(err[:, 2]).max() < np.radians(1.0)
    assert len(wide) <= 0.25 * (len(keep) - 1), (len(wide), len(keep))


@pytest.mark.parametrize("look_ahead", [True, False])
def test_a_contested_step_is_decided_by_the_next_scan(lap, monkeypatch, look_ahead: bool) -> None:
    """One step's contest is rigged: a place 0.4 m aside wins it, the true one comes second. The other contender
    goes on too; the next scan fits on from the true place better, so that branch is kept, counted, and every step
    is right. Without the look-ahead (no contest is close enough to fork) the wrong step stays."""
    import bagtools.odometry.frontend as frontend
    from bagtools.odometry.prior import Match

    if not look_ahead:
        monkeypatch.setattr(frontend, "CONTEST_MARGIN", -1.0)
    steps, truth = lap
    keep = np.arange(0, len(steps), 5)
    real, rigged_at = LaserOdometry._decide, 6

    def rigged(self, points, kf, matches, best, prior):
        winner, ambiguous, other = real(self, points, kf, matches, best, prior)
        if len(self.run.steps) == rigged_at and self._fork is None and not getattr(self, "_rigged", False):
            self._rigged = True
            wrong = Match(winner.pose + np.array([0.0, 0.4, 0.0]), winner.score, winner.covariance, "search")
            return wrong, False, winner
        return winner, ambiguous, other

    monkeypatch.setattr(LaserOdometry, "_decide", rigged)
    front = register(steps, truth, keep)
    err = step_errors(front.run.poses(), truth[keep])
    worst = np.hypot(err[:, 0], err[:, 1]).max()
    if look_ahead:
        assert front.summary_counts()["revised_by_the_next_scan"] >= 1 and worst < 0.03, (front.counts, worst)
    else:
        assert front.counts["revised_by_the_next_scan"] == 0 and worst > 0.3, worst
