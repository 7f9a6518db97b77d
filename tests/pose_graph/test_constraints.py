"""Loop-closure search: candidates within reach, matches against local maps, the consistency checks."""

from __future__ import annotations

import numpy as np
import pytest

from bagtools.pose_graph.consistency import ConsistencyCheck
from bagtools.pose_graph.constraints import LoopClosureSearch, voxel_subsample
from bagtools.pose_graph.loops import LoopCandidate, LoopKind, LoopOptions, LoopOutcome
from bagtools.transforms import se2_between, se2_compose
from bagtools_simulate.world.world import World
from tests.standin import true_poses_at_scans


def _search_over(front, poses_of_keyframes: np.ndarray, options: LoopOptions | None = None) -> LoopClosureSearch:
    search = LoopClosureSearch(options)
    keyframes = front.keyframe_indexes
    for n, k in enumerate(keyframes):
        motion = None if n == 0 else se2_between(poses_of_keyframes[n - 1], poses_of_keyframes[n])
        search.add_keyframe(front.steps[k].points_base, motion)
    return search


def test_voxel_subsample_keeps_one_point_per_cell() -> None:
    pts = np.array([[0.01, 0.01], [0.02, 0.03], [0.5, 0.5], [0.51, 0.52], [-0.3, 0.2]])
    out = voxel_subsample(pts, 0.1)
    assert len(out) == 3 and np.allclose(out, [[0.01, 0.01], [0.5, 0.5], [-0.3, 0.2]])
    assert voxel_subsample(np.zeros((0, 2)), 0.1).shape == (0, 2)


def test_candidates_skip_the_recent_path_and_take_the_nearest_of_each_pass(figure8_bag, figure8_front) -> None:
    _, truth = true_poses_at_scans(figure8_bag)
    kf = np.array(figure8_front.keyframe_indexes)
    poses = truth[kf]
    search = _search_over(figure8_front, poses, LoopOptions(max_candidates=10))
    path = np.asarray(search.path_m)
    new = len(kf) - 1
    distance = path[new] - path  # along the chain only, as before any loop
    found = search.candidates(new, poses, distance, [])
    assert found, "the figure eight comes back to places it has seen"
    for a in found:
        assert path[new] - path[a] >= 5.0
        reach = 5.0 + 3.0 * 0.03 * distance[a]
        assert np.hypot(*(poses[a, :2] - poses[new, :2])) <= reach
    assert len(found) == len(set(found)) and all(np.diff(sorted(found)) > 1)  # one per pass
    # an accepted loop from the newest keyframe ties the pass it landed in
    assert found[0] not in search.candidates(new, poses, distance, [(found[0], new)])


def _drifted(poses: np.ndarray, new: int, error: list[float]) -> np.ndarray:
    """``poses`` with the recent keyframes (``new`` and the 3 before) moved together so that ``new`` is off by ``error``."""
    out = poses.copy()
    moved = se2_compose(poses[new], error)
    D = se2_compose(moved, se2_between(poses[new], np.zeros(3)))  # moved @ inv(poses[new])
    for k in range(new - 3, new + 1):
        out[k] = se2_compose(D, poses[k])
    return out


def test_match_recovers_the_true_relative_pose_from_a_wrong_guess(figure8_bag, figure8_front) -> None:
    _, truth = true_poses_at_scans(figure8_bag)
    kf = np.array(figure8_front.keyframe_indexes)
    poses = truth[kf]
    search = _search_over(figure8_front, poses)
    new = len(kf) - 1
    old = search.candidates(new, poses, np.asarray(search.path_m[new]) - np.asarray(search.path_m), [])[0]
    cand = search.match(old, new, _drifted(poses, new, [0.25, -0.2, 0.08]), (0.15, 0.05))
    truth_rel = se2_between(poses[old], poses[new])
    err = se2_between(truth_rel, cand.T_old_new)
    assert cand.score >= 0.5 and np.hypot(err[0], err[1]) < 0.02 and abs(err[2]) < 0.01, (cand.score, err)
    assert np.allclose(cand.window[:2], 0.45) and np.isclose(cand.window[2], 0.15)
    sd = np.sqrt(np.diag(cand.covariance))
    assert (sd >= [0.01, 0.01, 0.005]).all() and (sd < [0.1, 0.1, 0.05]).all()
    # a window that cannot reach the truth finds nothing good enough
    missed = search.match(old, new, _drifted(poses, new, [1.5, 1.0, 0.0]), (0.01, 0.01))
    assert missed.T_old_new is None or np.hypot(*se2_between(truth_rel, missed.T_old_new)[:2]) > 0.2


def test_global_match_finds_the_place_whatever_the_estimate_says(figure8_bag, figure8_front) -> None:
    """The estimate puts the newest keyframe 3.6 m and 34 degrees off: the local search's window (sized by an
    uncertainty that does not know the error) misses the truth; the global search over the old maps finds it."""
    _, truth = true_poses_at_scans(figure8_bag)
    kf = np.array(figure8_front.keyframe_indexes)
    poses = truth[kf]
    search = _search_over(figure8_front, poses)
    new = len(kf) - 1
    drifted = _drifted(poses, new, [3.0, -2.0, 0.6])
    old = search.candidates(new, poses, np.asarray(search.path_m[new]) - np.asarray(search.path_m), [])[0]
    local = search.match(old, new, drifted, (0.15, 0.05))
    truth_rel = se2_between(poses[old], poses[new])
    assert local.T_old_new is None or np.hypot(*se2_between(truth_rel, local.T_old_new)[:2]) > 0.5
    tiles = search.global_tiles(new, drifted)
    found = [search.match(a, new, drifted, (0.0, 0.0), kind=LoopKind.GLOBAL) for a in tiles]
    assert all(c.kind == LoopKind.GLOBAL and np.allclose(c.window, [4.0, 4.0, np.pi]) for c in found)
    best = max((c for c in found if c.T_old_new is not None), key=lambda c: c.score)
    err = se2_between(se2_between(poses[best.old], poses[new]), best.T_old_new)
    assert best.score >= 0.6 and np.hypot(err[0], err[1]) < 0.05 and abs(err[2]) < 0.02, (best.score, err)


def _corridor_search(junction: bool) -> tuple[LoopClosureSearch, np.ndarray]:
    """Keyframes 1 m apart along a 3 m wide corridor (walls at y = +-1.5 m, seen to 8 m), driven twice: keyframes
    0..19 and 20..39 over the same x. With ``junction``, a hall opening off it at x = 10..14 tells the places apart."""
    wall_x = np.arange(-5.0, 30.0, 0.05)
    left = wall_x if not junction else wall_x[(wall_x < 10.0) | (wall_x > 14.0)]
    world = [np.c_[left, np.full_like(left, 1.5)], np.c_[wall_x, np.full_like(wall_x, -1.5)]]
    if junction:  # the left wall opens at x = 10..14 into a hall (walls x = 10, y = 6, and x = 14 up to y = 4)
        y, x, y2 = np.arange(1.5, 6.0, 0.05), np.arange(10.0, 14.0, 0.05), np.arange(1.5, 4.0, 0.05)
        world += [np.c_[np.full_like(y, 10.0), y], np.c_[x, np.full_like(x, 6.0)], np.c_[np.full_like(y2, 14.0), y2]]
    world = np.vstack(world)
    xs = np.r_[np.arange(20.0), np.arange(20.0)]
    poses = np.c_[xs, np.zeros(40), np.zeros(40)]
    search = LoopClosureSearch(LoopOptions())
    for k, x in enumerate(xs):
        seen = world[np.abs(world[:, 0] - x) < 8.0] - [x, 0.0]
        search.add_keyframe(seen, None if k == 0 else np.array([1.0, 0.0, 0.0]))
    return search, poses


@pytest.mark.parametrize("junction", [False, True])
def test_a_global_match_in_a_corridor_is_a_look_alike(junction: bool) -> None:
    """A plain corridor matches all along itself (and turned around): the global search refuses it; at a
    junction the place is found."""
    search, poses = _corridor_search(junction)
    cand = search.match(10, 30, poses, (0.0, 0.0), kind=LoopKind.GLOBAL)
    if not junction:
        assert cand.status == LoopOutcome.LOOK_ALIKE and cand.T_old_new is None
    else:
        assert cand.status != LoopOutcome.LOOK_ALIKE and cand.T_old_new is not None
        assert np.hypot(*cand.T_old_new[:2]) < 0.05 and abs(cand.T_old_new[2]) < 0.01


@pytest.mark.parametrize("junction", [False, True])
def test_a_wide_local_window_that_holds_a_look_alike_is_refused(junction: bool) -> None:
    """A local match searched in a window as wide as a corridor's look-alikes are apart asks whether another place
    of its window scores as well, and is refused when one does (no second match could tell the two apart: the
    look-alike shifts every match of the corridor alike); a narrow window is not asked."""
    search, poses = _corridor_search(junction)
    wide = search.match(10, 30, poses, (1.0, 0.1))
    assert wide.window[0] >= search.options.wide_window_m
    assert wide.look_alike is (not junction)
    if junction:  # the junction makes the place unique
        assert wide.T_old_new is not None and wide.status != LoopOutcome.LOOK_ALIKE
    else:
        assert wide.T_old_new is None and wide.status == LoopOutcome.LOOK_ALIKE
    narrow = search.match(10, 30, poses, (0.1, 0.03))
    assert narrow.window[0] < search.options.wide_window_m
    assert narrow.T_old_new is not None and narrow.look_alike is None
    # a window cut short by the search radius (5 m for 2 sigmas of 3 m) cannot say there is no look-alike
    short = search.match(10, 30, poses, (3.0, 0.1))
    assert short.window[0] == search.options.search_radius_m and short.look_alike is True


def test_only_the_one_good_place_of_a_wide_window_is_followed_up() -> None:
    poses, path = _retraced_corridor()
    check = ConsistencyCheck(LoopOptions(), path)
    same = np.zeros(3)
    # new maps that share keyframes (new_map_keyframes = 4): none confirms another
    local = _cand(2, 22, same, same, (0.6, 0.1))
    local.look_alike = False  # its wide window held no look-alike
    narrow = _cand(3, 23, same, same, (0.35, 0.05))  # a narrow window was not asked
    narrow.window = np.array([0.6, 0.6, 0.15])
    look_alike = _cand(5, 25, same, same, (0.9, 0.2))
    look_alike.look_alike = True
    follow_up = _cand(4, 24, same, same, (0.6, 0.1))
    follow_up.kind = LoopKind.FOLLOW_UP
    for c in (local, narrow, look_alike, follow_up):
        assert check.review(c, poses) == [] and c.status == LoopOutcome.PENDING
    assert check.to_follow_up() == [local]


def _room(furniture: list[list[list[float]]]) -> World:
    """An 8 m x 5 m room (free for 0 < x < 8, 0 < y < 5) with ``furniture``: solid boxes' outlines [[x, y], ...]."""
    shell = {"vertices": [[-0.2, -0.2], [8.2, -0.2], [8.2, 5.2], [-0.2, 5.2]],
             "holes": [[[0, 0], [8, 0], [8, 5], [0, 5]]], "z": [0, 2]}
    return World.from_dict({"name": "room", "polygons": [shell] + [{"vertices": f, "z": [0, 2]} for f in furniture],
                            "spawn": {"x": 1.0, "y": 1.5}})


#: A partition across the room's right half, and a bench along its top left wall.
PARTITION = [[4.5, 0.8], [4.9, 0.8], [4.9, 3.5], [4.5, 3.5]]
BENCH = [[1.0, 3.3], [4.0, 3.3], [4.0, 3.7], [1.0, 3.7]]


def _rooms_search(old_room: World, new_room: World) -> tuple[LoopClosureSearch, np.ndarray]:
    """Keyframes 0..6 in ``old_room`` and 20..24 in ``new_room``, at the same places (x = 1..2.2 m, y = 1.5 m; the
    ones between far away): the estimate says the new ones are back where the old ones were."""
    xs = 1.0 + 0.2 * np.arange(7)
    places = np.r_[xs, np.full(13, 50.0), xs[:5]]
    poses = np.c_[places, np.full(25, 1.5), np.zeros(25)]
    search = LoopClosureSearch(LoopOptions())
    bearings = np.linspace(-np.pi, np.pi, 360, endpoint=False)
    for k, pose in enumerate(poses):
        room = old_room if k < 20 else new_room
        ranges = room.raycast_2d(pose[:2], bearings, 1.0, 20.0) if pose[0] < 10 else np.full(360, 3.0)
        seen = np.c_[np.cos(bearings), np.sin(bearings)] * ranges[:, None]
        search.add_keyframe(seen[np.isfinite(ranges)], None if k == 0 else se2_between(poses[k - 1], pose))
    return search, poses


def test_a_room_of_the_same_shape_furnished_otherwise_is_not_the_place() -> None:
    """The walls line up, so the scans match; but each room's furniture stands where the other's laser saw the floor.
    The match is refused. The place itself matches, and so does a room where only one visit saw a new piece (the
    world changed: a door shut, a person passing)."""
    furnished = _room([PARTITION])
    for new_room, refused in ((_room([BENCH]), True), (_room([PARTITION]), False), (_room([PARTITION, BENCH]), False)):
        search, poses = _rooms_search(furnished, new_room)
        cand = search.match(3, 24, poses, (0.1, 0.03))
        assert cand.score >= search.options.min_score
        if refused:
            assert cand.status == LoopOutcome.SEES_THROUGH and cand.T_old_new is None
        else:
            err = se2_between(se2_between(poses[3], poses[24]), cand.T_old_new)
            assert cand.status != LoopOutcome.SEES_THROUGH and np.hypot(err[0], err[1]) < 0.05 and abs(err[2]) < 0.02


def _cand(old: int, new: int, T: np.ndarray, guess: np.ndarray, sigma: tuple[float, float]) -> LoopCandidate:
    return LoopCandidate(old, new, guess, np.array([1.0, 1.0, 0.3]), sigma, T, np.eye(3) * 1e-4, 0.8)


def _retraced_corridor() -> tuple[np.ndarray, list[float]]:
    """A straight corridor, keyframes 1 m apart along x, poses exact: old keyframes 0..9, new ones 20..29 on top
    of them. (poses (30,3), path_m)."""
    poses = np.zeros((30, 3))
    poses[:10, 0] = np.arange(10)
    poses[20:, 0] = np.arange(10)
    return poses, list(np.arange(30, dtype=float) * 1.0)


def test_consistency_check() -> None:
    poses, path = _retraced_corridor()
    check = ConsistencyCheck(LoopOptions(), path)
    same = np.zeros(3)
    sure = _cand(2, 22, same, same, (0.05, 0.01))
    assert check.review(sure, poses) == [sure] and sure.status == LoopOutcome.ACCEPTED
    off = _cand(3, 23, np.array([1.0, 0.0, 0.0]), same, (0.05, 0.01))  # 1 m off a sure estimate
    assert check.review(off, poses) == [] and off.status == LoopOutcome.INCONSISTENT
    # unsure estimate: one match waits, a second consistent one from another keyframe confirms both
    check = ConsistencyCheck(LoopOptions(), path)
    first = _cand(4, 24, same, same, (0.6, 0.1))
    assert check.review(first, poses) == [] and first.status == LoopOutcome.PENDING
    aliased = _cand(5, 25, np.array([0.9, 0.0, 0.0]), same, (0.6, 0.1))  # a look-alike 0.9 m further on
    assert check.review(aliased, poses) == [] and aliased.status == LoopOutcome.PENDING
    # a match whose new map shares keyframes with the first's (new_map_keyframes = 4) repeats the same evidence
    overlapping = _cand(6, 26, same, same, (0.6, 0.1))
    assert check.review(overlapping, poses) == [] and overlapping.status == LoopOutcome.PENDING
    second = _cand(9, 29, same, same, (0.6, 0.1))  # its new map (25..29) shares none with the first's (20..24)
    assert set(map(id, check.review(second, poses))) == {id(second), id(first)}
    assert aliased.status == LoopOutcome.PENDING and check.expire(newest=50) == [aliased, overlapping]
    assert aliased.status == LoopOutcome.UNCONFIRMED


def test_a_global_match_is_gated_loosely_by_the_drift_model_and_needs_a_follow_up() -> None:
    # The estimate puts the new pass (keyframes 20..29) 8 m and 40 degrees away from the old one it retraces.
    poses = np.zeros((30, 3))
    poses[:10, 0] = np.arange(10)
    poses[20:] = [se2_compose([8.0, 3.0, 0.7], [k, 0.0, 0.0]) for k in range(10)]
    path = list(np.arange(30, dtype=float) * 1.0)
    check = ConsistencyCheck(LoopOptions(), path)
    same = np.zeros(3)
    # after a short stretch of path (drift model: 0.3 m, 0.1 rad) 8.5 m and 40 degrees is a look-alike, not drift
    near = LoopCandidate(2, 22, same, np.array([4.0, 4.0, np.pi]), (0.3, 0.1), same, np.eye(3) * 1e-4, 0.8,
                         kind=LoopKind.GLOBAL)
    assert check.review(near, poses) == [] and near.status == LoopOutcome.INCONSISTENT
    # after a long loop (drift model: 3 m, 0.5 rad) it is a correction within 5 sigmas
    found = LoopCandidate(2, 22, same, np.array([4.0, 4.0, np.pi]), (3.0, 0.5), same, np.eye(3) * 1e-4, 0.8,
                          kind=LoopKind.GLOBAL, look_alike=False)
    assert check.review(found, poses) == [] and found.status == LoopOutcome.PENDING and check.to_follow_up() == [found]
    # a sure local match elsewhere does not confirm it; a follow-up where it puts keyframe 28 does
    wrong = LoopCandidate(2, 28, same, np.array([0.3, 0.3, 0.1]), (0.05, 0.01), np.array([1.5, 0.0, 0.0]),
                          np.eye(3) * 1e-4, 0.8, kind=LoopKind.FOLLOW_UP)
    assert check.review(wrong, poses) == [] and found.status == LoopOutcome.PENDING
    guess = se2_compose(found.T_old_new, se2_between(poses[22], poses[28]))
    follow = LoopCandidate(2, 28, guess, np.array([0.3, 0.3, 0.1]), (0.2, 0.06), guess, np.eye(3) * 1e-4, 0.8,
                           kind=LoopKind.FOLLOW_UP)
    assert set(map(id, check.review(follow, poses))) == {id(found), id(follow)}
    assert found.status == LoopOutcome.ACCEPTED and not check.to_follow_up()


def test_a_loop_is_supported_by_a_consistent_loop_from_other_scans() -> None:
    poses, path = _retraced_corridor()
    check = ConsistencyCheck(LoopOptions(), path)
    same = np.zeros(3)
    first = _cand(2, 22, same, same, (0.05, 0.01))
    check.review(first, poses)
    assert not check.supported(first, poses)  # alone
    near = _cand(3, 23, same, same, (0.05, 0.01))  # its new map shares keyframes with the first's: no support
    check.review(near, poses)
    assert not check.supported(first, poses)
    far_wrong = _cand(8, 28, np.array([3.0, 0.0, 0.0]), np.array([3.0, 0.0, 0.0]), (0.6, 0.1))
    check.accepted.append(far_wrong)  # as if accepted earlier: 3 m off, beyond the cycle gate (1.5 m over these 12 m of chain)
    assert not check.supported(first, poses)
    far = _cand(8, 28, same, same, (0.05, 0.01))
    check.review(far, poses)
    assert check.supported(first, poses) and check.supported(far, poses)


def test_a_follow_up_does_not_support_its_own_match_against_the_graph() -> None:
    """A follow-up repeats its match's error: it lets the match into the graph, but when the graph finds the match
    an outlier, only a match searched independently may speak for it."""
    poses, path = _retraced_corridor()
    check = ConsistencyCheck(LoopOptions(), path)
    same = np.zeros(3)
    match = _cand(2, 22, same, same, (0.6, 0.1))
    follow = _cand(2, 28, same, same, (0.2, 0.05))
    follow.kind, follow.follows = LoopKind.FOLLOW_UP, match
    check.accepted += [match, follow]
    assert not check.supported(match, poses) and not check.supported(follow, poses)
    independent = _cand(8, 28, same, same, (0.6, 0.1))  # searched on its own from the same scans as the follow-up
    check.accepted.append(independent)
    assert check.supported(match, poses)


def test_global_tiles_cover_the_old_path_once_per_tile() -> None:
    search = LoopClosureSearch(LoopOptions(global_tile_m=4.0, global_max_tiles=100))
    for k in range(70):  # a straight 69 m path, keyframes 1 m apart
        search.add_keyframe(np.zeros((0, 2)), None if k == 0 else np.array([1.0, 0.0, 0.0]))
    poses = np.c_[np.arange(70.0), np.zeros(70), np.zeros(70)]
    tiles = search.global_tiles(69, poses)
    path = np.asarray(search.path_m)
    assert sorted(tiles) == tiles[::-1]  # the nearest first
    assert all(path[69] - path[a] >= 8.0 for a in tiles) and len(set(np.floor(path[tiles] / 4.0))) == len(tiles)
    assert len(tiles) == 16  # old keyframes 0..60 (those of the new and old maps excluded) in 16 tiles of 4 m
    # due once 30 m have passed since the last accepted loop and since the last global search
    assert not search.global_due(20, None) and search.global_due(30, None) and not search.global_due(59, None)
    assert not search.global_due(69, 40) and search.global_due(69, 25)


@pytest.mark.parametrize("field,value", [("search_radius_m", 0.0), ("min_score", 1.5), ("max_candidates", 0),
                                         ("old_map_keyframes", -1), ("drift_per_m", float("nan")),
                                         ("global_min_score", -0.1), ("global_tile_m", 0.0), ("global_max_tiles", 0),
                                         ("max_seen_through", 1.5)])
def test_bad_loop_options(field: str, value: float) -> None:
    with pytest.raises(ValueError, match=field):
        LoopOptions(**{field: value})


def test_map_covariance_matches_a_monte_carlo_of_the_chain() -> None:
    rng = np.random.default_rng(4)
    search = LoopClosureSearch()
    motions = [None, np.array([0.5, 0.0, 0.2]), np.array([0.5, 0.1, -0.1]), np.array([0.4, 0.0, 0.3])]
    cov = np.diag([1e-4, 4e-4, 1e-4])
    for m in motions:
        search.add_keyframe(np.zeros((0, 2)), m, None if m is None else cov)
    predicted = search.map_covariance(1, range(0, 4))
    samples = []
    for _ in range(2000):
        noisy = [m + rng.multivariate_normal(np.zeros(3), cov) for m in motions[1:]]
        before = se2_between(noisy[0], np.zeros(3))  # keyframe 0 in keyframe 1's frame
        after1 = noisy[1]
        after2 = se2_compose(noisy[1], noisy[2])
        samples.append([before, after1, after2])
    samples = np.array(samples)  # (draws, keyframe, 3)
    empirical = sum(np.cov(samples[:, k].T) for k in range(3)) / 4
    assert np.allclose(predicted, empirical, rtol=0.2, atol=2e-6), (predicted, empirical)
