"""The tracked poses smoothed with the laser odometry: the map matches' noise averaged out, a wrong match held
by the motion, a kidnap not smoothed over, a stretch with no map match left as tracked, two visits of a place
tied by their scans."""

from __future__ import annotations

import dataclasses

import numpy as np

from bagtools.commands.localize.smoother import map_offset, revisit_factors, smooth_track
from bagtools.odometry.steps import ScanStep
from bagtools.transforms import se2_between, se2_compose
from bagtools_simulate.world import World

COV = np.diag([1e-4, 1e-4, 3e-5])


def _path(n: int = 120) -> np.ndarray:
    """A robot driving an arc, 5 cm and 0.02 rad per scan (map frame)."""
    poses = [np.array([1.0, 2.0, 0.3])]
    for _ in range(n - 1):
        poses.append(se2_compose(poses[-1], np.array([0.05, 0.0, 0.02])))
    return np.array(poses)


def _steps(odometry: np.ndarray, rng: np.random.Generator, every: int = 5,
           noise: tuple[float, float, float] = (0.005, 0.005, 0.001)) -> list[ScanStep]:
    """Front-end steps over ``odometry`` poses (its own frame): each scan matched against the keyframe of
    ``every`` scans before it, with ``noise`` (standard deviations, m, m, rad)."""
    steps = []
    keyframe = 0
    for k, pose in enumerate(odometry):
        if k == 0:
            steps.append(ScanStep(0, pose, np.zeros((0, 2)), -1, np.zeros(3), COV, 1.0, "first", True))
            continue
        T = se2_between(odometry[keyframe], pose) + rng.normal(0.0, noise)
        steps.append(ScanStep(k * 100_000_000, pose, np.zeros((0, 2)), keyframe, T, COV, 0.9, "ndt", k % every == 0))
        if k % every == 0:
            keyframe = k
    return steps


def _error(poses: dict[int, np.ndarray], truth: np.ndarray) -> np.ndarray:
    return np.array([np.hypot(*(poses[k][:2] - truth[k][:2])) for k in sorted(poses)])


def test_the_map_matches_noise_is_averaged_out_and_a_wrong_match_is_held_by_the_motion() -> None:
    rng = np.random.default_rng(3)
    truth = _path()
    odometry = np.array([se2_compose(np.array([5.0, -3.0, 1.0]), se2_between(truth[0], p)) for p in truth])
    tracked = {k: p + rng.normal(0.0, [0.03, 0.03, 0.01]) for k, p in enumerate(truth)}
    tracked[60] = truth[60] + np.array([0.8, -0.5, 0.2])  # a look-alike place, one scan
    smoothed = smooth_track(_steps(odometry, rng), tracked, matched=set(tracked))
    raw, smooth = _error(tracked, truth), _error(smoothed, truth)
    assert smooth.mean() < 0.5 * np.delete(raw, 60).mean(), (smooth.mean(), raw.mean())
    assert smooth[60] < 0.03 and smooth.max() < 0.05


def test_the_graph_is_cut_where_the_robot_was_lost_a_kidnap_is_not_smoothed_over() -> None:
    """From scan 60 on the robot is 2.5 m away (carried); the odometry saw nothing."""
    rng = np.random.default_rng(4)
    path = _path()
    truth = path.copy()
    truth[60:] = np.array([se2_compose(np.array([2.5, 0.0, 0.0]), p) for p in path[60:]])
    steps = _steps(path, rng)
    tracked = {k: p + rng.normal(0.0, [0.01, 0.01, 0.003]) for k, p in enumerate(truth)}
    cut = smooth_track(steps, tracked, matched=set(tracked), cuts=[60])
    assert _error(cut, truth).max() < 0.05
    joined = smooth_track(steps, tracked, matched=set(tracked))  # without the cut, the odometry ties them
    assert _error(joined, truth).max() > 0.5


def _out_and_turn_back() -> np.ndarray:
    """A robot driving 3 m, turning round on the spot, driving back and turning round again (map frame)."""
    poses = [np.array([1.0, 2.0, 0.3])]
    for motion in [(0.05, 0.0, 0.0)] * 60 + [(0.0, 0.0, np.pi / 30)] * 30 + [(0.05, 0.0, 0.0)] * 60 + [
            (0.0, 0.0, -np.pi / 30)] * 30:
        poses.append(se2_compose(poses[-1], np.array(motion)))
    return np.array(poses)


def test_the_map_matches_offset_from_the_base_shows_where_the_robot_turns_and_is_taken_out() -> None:
    """Every map match puts the base 2 cm ahead and 5 mm to the right of where it is (a raytraced map's walls
    behind what the laser saw): driving straight, the laser odometry cannot tell; turning round, the matches move
    by twice that against it. The offset is found, and the smoothed poses are the base's, not the matches'."""
    rng = np.random.default_rng(8)
    truth = _out_and_turn_back()
    offset = np.array([0.02, -0.005])
    steps = _steps(truth, rng, noise=(0.0005, 0.0005, 0.0001))  # a short drive: the laser odometry holds
    tracked = {k: se2_compose(p, np.r_[offset, 0.0]) + rng.normal(0.0, [0.005, 0.005, 0.002])
               for k, p in enumerate(truth)}
    found = map_offset(steps, tracked, matched=set(tracked))
    assert np.hypot(*(found - offset)) < 0.003, found
    kept = _error(smooth_track(steps, tracked, matched=set(tracked)), truth)
    taken_out = _error(smooth_track(steps, tracked, matched=set(tracked), offset=found), truth)
    assert kept.mean() > 0.005 and taken_out.mean() < 0.4 * kept.mean(), (kept.mean(), taken_out.mean())
    straight = np.array([se2_compose(truth[0], np.array([0.05 * k, 0.0, 0.0])) for k in range(120)])
    ahead = {k: se2_compose(p, np.r_[offset, 0.0]) for k, p in enumerate(straight)}
    assert np.hypot(*map_offset(_steps(straight, rng), ahead, matched=set(ahead))) < 0.002  # nothing says it
    assert not map_offset(steps, {}, matched=()).any()


def test_a_match_the_map_explains_in_part_weighs_less() -> None:
    """Scans 50-70 see a part of the building the map saw only from afar: their matches score 0.4 where the
    others score 0.9, and lie 6 cm off. Weighed by how well the map explains them, they pull the path less."""
    rng = np.random.default_rng(9)
    truth = _path()
    steps = _steps(truth, rng, noise=(0.001, 0.001, 0.0002))
    tracked = {k: p + rng.normal(0.0, [0.005, 0.005, 0.002]) for k, p in enumerate(truth)}
    scores = {k: 0.9 for k in tracked}
    for k in range(50, 70):
        tracked[k] = tracked[k] + np.array([0.06, 0.0, 0.0])
        scores[k] = 0.4
    alike = _error(smooth_track(steps, tracked, matched=set(tracked)), truth)[50:70]
    weighed = _error(smooth_track(steps, tracked, matched=set(tracked), scores=scores), truth)[50:70]
    assert weighed.mean() < 0.6 * alike.mean(), (weighed.mean(), alike.mean())


def test_a_stretch_with_no_map_match_keeps_the_tracked_poses() -> None:
    rng = np.random.default_rng(5)
    truth = _path(60)
    steps = _steps(truth, rng)
    tracked = {k: p.copy() for k, p in enumerate(truth)}
    tracked[40] = truth[40] + 0.3  # carried by the motion, not matched: no map factor, and cut off
    smoothed = smooth_track(steps, tracked, matched=set(range(30)), cuts=[30])
    for k in range(30, 60):
        np.testing.assert_array_equal(smoothed[k], tracked[k])
    assert smooth_track(steps, {}, matched=()) == {}


def test_a_robot_standing_still_gets_no_surer_of_the_map_for_each_scan(monkeypatch) -> None:
    """120 scans driving, then 300 standing still where the map match is 5 cm off, the same 5 cm every scan (the
    map's error at that place; the laser odometry sees no motion). Weighed per scan, the standing scans outvote
    the drive and pull the robot there most of the way to the map's error; weighed per MAP_SPAN_M of path, they
    count as about one scan, and the drive's matches place it."""
    from bagtools.commands.localize import smoother

    rng = np.random.default_rng(6)
    truth = np.vstack([_path(), np.repeat(_path()[-1:], 300, axis=0)])
    steps = [s if k < 120 else dataclasses.replace(s, T_ref_cur=se2_between(truth[s.reference], truth[k]))
             for k, s in enumerate(_steps(truth, rng))]
    tracked = {k: p + rng.normal(0.0, [0.02, 0.02, 0.005]) for k, p in enumerate(truth[:120])}
    tracked.update({k: truth[k] + np.array([0.05, 0.0, 0.0]) for k in range(120, len(truth))})
    standing = _error(smooth_track(steps, tracked, matched=set(tracked)), truth)[120:]
    assert standing.mean() < 0.025, standing.mean()
    monkeypatch.setattr(smoother, "MIN_MAP_SHARE", 1.0)  # every scan a full map match
    assert _error(smooth_track(steps, tracked, matched=set(tracked)), truth)[120:].mean() > 0.04


def _out_and_back() -> tuple[np.ndarray, list[np.ndarray]]:
    """A robot driving 10 m down a room with boxes along its walls and back (base poses, map frame), and its
    360-degree scans (points in the base frame, 1 cm noise)."""
    def box(x0: float, y0: float, x1: float, y1: float) -> dict:
        return {"vertices": [[x0, y0], [x1, y0], [x1, y1], [x0, y1]], "z": [0.0, 1.0]}

    polygons = [box(-2.0, 2.0, 13.0, 2.2), box(-2.0, -2.2, 13.0, -2.0), box(-2.2, -2.2, -2.0, 2.2),
                box(13.0, -2.2, 13.2, 2.2)]
    for x, y in ((0.5, 1.6), (2.3, -2.0), (3.9, 1.5), (5.2, -1.7), (7.4, 1.7), (8.8, -2.0), (10.6, 1.4)):
        polygons.append(box(x, y, x + 0.4, y + 0.4))
    world = World.from_dict({"name": "room", "polygons": polygons, "spawn": {"x": 0.0, "y": 0.0, "yaw": 0.0}})
    out = [np.array([0.1 * k, -0.3, 0.0]) for k in range(100)]
    turn = [np.array([10.0, -0.3 + 0.6 * k / 20, np.pi * k / 20]) for k in range(1, 21)]
    back = [np.array([10.0 - 0.1 * k, 0.3, np.pi]) for k in range(1, 100)]
    truth = np.array(out + turn + back)
    rng = np.random.default_rng(7)
    angles = np.linspace(-np.pi, np.pi, 360, endpoint=False)
    scans = []
    for pose in truth:
        ranges = world.raycast_2d(pose[:2], pose[2] + angles, 0.2, 10.0)
        seen = np.isfinite(ranges)
        r = ranges[seen] + rng.normal(0.0, 0.01, np.count_nonzero(seen))
        scans.append(np.c_[r * np.cos(angles[seen]), r * np.sin(angles[seen])])
    return truth, scans


def test_revisits_tie_two_visits_of_a_place_by_their_scans_not_by_the_map() -> None:
    """Out and back along a room: the map places the robot 3 cm ahead of where it is, both ways (a raytraced
    map's walls lie a little behind what the laser sees), so the two visits disagree by 6 cm; the laser odometry
    turned 2 degrees too few over the turn. The revisits, matched scans to scans, say where the visits lie
    relative to each other, and the smoothed poses follow them."""
    truth, scans = _out_and_back()
    odometry = [truth[0]]
    for k in range(1, len(truth)):
        step = se2_between(truth[k - 1], truth[k])
        odometry.append(se2_compose(odometry[-1], step * [1.0, 1.0, 1.0 - 0.035 * (100 <= k < 120)]))
    steps = []
    keyframe = 0
    for k, (pose, points) in enumerate(zip(odometry, scans)):
        if k == 0:
            steps.append(ScanStep(0, pose, points, -1, np.zeros(3), COV, 1.0, "first", True))
            continue
        steps.append(ScanStep(k * 100_000_000, pose, points, keyframe, se2_between(odometry[keyframe], pose), COV,
                              0.9, "ndt", k % 5 == 0))
        keyframe = k if k % 5 == 0 else keyframe
    tracked = {k: se2_compose(p, np.array([0.03, 0.0, 0.0])) for k, p in enumerate(truth)}

    revisits = revisit_factors(steps, tracked)
    assert len(revisits) >= 10
    for a, b, T, _ in revisits:  # the way back sees again what the way out saw, at least 8 m of path later
        assert a < 100 <= 120 <= b
        off = se2_between(se2_between(truth[a], truth[b]), T)
        assert np.hypot(off[0], off[1]) < 0.015 and abs(off[2]) < 0.005, (a, b, off)

    def apart(poses: dict[int, np.ndarray]) -> float:
        """Mean error (m) of where the revisits' pairs lie relative to each other."""
        return float(np.mean([np.hypot(*se2_between(se2_between(truth[a], truth[b]),
                                                    se2_between(poses[a], poses[b]))[:2]) for a, b, _, _ in revisits]))

    without = smooth_track(steps, tracked, matched=set(tracked))
    joined = smooth_track(steps, tracked, matched=set(tracked), revisits=revisits)
    assert apart(tracked) > 0.05 and apart(without) > 0.04
    assert apart(joined) < 0.5 * apart(without), (apart(joined), apart(without))
    # a way back the map puts 0.6 m from where the robot drove: no window around it holds the way out's scans
    moved = {k: p + (np.array([0.6, 0.0, 0.0]) if k >= 120 else 0.0) for k, p in tracked.items()}
    assert revisit_factors(steps, moved) == []
