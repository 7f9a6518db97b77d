"""The tracked poses smoothed with the laser odometry: the map matches' noise averaged out, a wrong match held
by the motion, a kidnap not smoothed over, a stretch with no map match left as tracked."""

from __future__ import annotations

import numpy as np

from bagtools.localize.smoother import smooth_track
from bagtools.ndtodom.steps import ScanStep
from bagtools.transforms import se2_between, se2_compose

COV = np.diag([1e-4, 1e-4, 3e-5])


def _path(n: int = 120) -> np.ndarray:
    """A robot driving an arc, 5 cm and 0.02 rad per scan (map frame)."""
    poses = [np.array([1.0, 2.0, 0.3])]
    for _ in range(n - 1):
        poses.append(se2_compose(poses[-1], np.array([0.05, 0.0, 0.02])))
    return np.array(poses)


def _steps(odometry: np.ndarray, rng: np.random.Generator, every: int = 5) -> list[ScanStep]:
    """Front-end steps over ``odometry`` poses (its own frame): each scan matched against the keyframe of
    ``every`` scans before it, with 5 mm noise."""
    steps = []
    keyframe = 0
    for k, pose in enumerate(odometry):
        if k == 0:
            steps.append(ScanStep(0, pose, np.zeros((0, 2)), -1, np.zeros(3), COV, 1.0, "first", True))
            continue
        T = se2_between(odometry[keyframe], pose) + rng.normal(0.0, [0.005, 0.005, 0.001])
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
