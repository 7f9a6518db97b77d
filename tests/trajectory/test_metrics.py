"""APE / RPE against evo itself on the same trajectories (evo is a test dependency)."""

from __future__ import annotations

import numpy as np
import pytest
from evo.core import metrics, sync
from evo.core.trajectory import PoseTrajectory3D

from bagtools.errors import BagtoolsError
from bagtools.trajectory import Trajectory, ape_translation, associate, rpe_translation
from bagtools.trajectory.metrics import ErrorStats, path_pairs
from bagtools.transforms import eul2rotm

T0_NS = 1_700_000_000_000_000_000


def _random_walk(rng: np.random.Generator, n: int, step_m: float = 0.05) -> np.ndarray:
    """(n,4,4) poses of a wandering 3D body."""
    yaw = np.cumsum(rng.normal(0, 0.05, n))
    pitch, roll = rng.normal(0, 0.02, n), rng.normal(0, 0.02, n)
    R = eul2rotm(np.column_stack((yaw, pitch, roll)))
    steps = np.einsum("nij,j->ni", R, [step_m, 0, 0]) + rng.normal(0, 0.005, (n, 3))
    T = np.zeros((n, 4, 4))
    T[:, :3, :3], T[:, :3, 3], T[:, 3, 3] = R, np.cumsum(steps, axis=0), 1.0
    return T


def _noisy(rng: np.random.Generator, T: np.ndarray, sd_m: float) -> np.ndarray:
    out = T.copy()
    out[:, :3, 3] += np.cumsum(rng.normal(0, sd_m, (len(T), 3)), axis=0)
    yaw = np.cumsum(rng.normal(0, 0.002, len(T)))
    out[:, :3, :3] = eul2rotm(np.column_stack((yaw, 0 * yaw, 0 * yaw))) @ T[:, :3, :3]
    return out


def _evo(traj: Trajectory) -> PoseTrajectory3D:
    return PoseTrajectory3D(poses_se3=list(traj.poses), timestamps=traj.stamps_ns / 1e9)


def _evo_stats(metric, ref: Trajectory, est: Trajectory) -> dict:
    r, e = sync.associate_trajectories(_evo(ref), _evo(est), max_diff=0.01)
    metric.process_data((r, e))
    return metric.get_all_statistics()


def _check(ours: ErrorStats, theirs: dict) -> None:
    for key in ("rmse", "mean", "median", "std", "min", "max", "sse"):
        assert getattr(ours, key) == pytest.approx(theirs[key], rel=1e-9, abs=1e-12), key


@pytest.fixture
def pair() -> tuple[Trajectory, Trajectory]:
    """A 30 Hz reference and a 5 Hz estimate with jittered stamps and some stamps without a partner."""
    rng = np.random.default_rng(3)
    n = 900
    stamps = T0_NS + np.arange(n, dtype=np.int64) * 33_333_333
    ref = Trajectory(stamps, _random_walk(rng, n))
    pick = np.arange(0, n, 6)
    est_stamps = stamps[pick] + rng.integers(-12_000_000, 12_000_000, pick.size)
    est = Trajectory(est_stamps, _noisy(rng, ref.poses[pick], 0.01))
    return ref, est


def test_association_matches_evo(pair) -> None:
    ref, est = pair
    r, e = associate(ref, est)
    er, ee = sync.associate_trajectories(_evo(ref), _evo(est), max_diff=0.01)
    assert len(r) == er.num_poses < len(est)  # some estimate stamps are more than 10 ms off
    np.testing.assert_array_equal(r.stamps_ns / 1e9, er.timestamps)
    np.testing.assert_allclose(e.positions, ee.positions_xyz)


def test_ape_equals_evo(pair) -> None:
    ref, est = pair
    _check(ape_translation(ref, est), _evo_stats(metrics.APE(metrics.PoseRelation.translation_part), ref, est))


@pytest.mark.parametrize("delta_m", [1.0, 0.5, 2.5])
def test_rpe_per_distance_equals_evo(pair, delta_m: float) -> None:
    ref, est = pair
    ours = rpe_translation(ref, est, delta_m=delta_m)
    evo_rpe = metrics.RPE(metrics.PoseRelation.translation_part, delta=delta_m, delta_unit=metrics.Unit.meters,
                          all_pairs=False)
    theirs = _evo_stats(evo_rpe, ref, est)
    assert ours.count == len(evo_rpe.error)
    _check(ours, theirs)


def test_path_pairs_steps_of_one_metre() -> None:
    positions = np.zeros((11, 3))
    positions[:, 0] = np.arange(11) * 0.4  # 0, 0.4, ..., 4.0 m
    # evo accumulates 0.4 + 0.4 + 0.4 = 1.2 >= 1, so every third pose starts a pair
    np.testing.assert_array_equal(path_pairs(positions, 1.0), [[0, 3], [3, 6], [6, 9]])


def test_identical_trajectories_have_zero_error(pair) -> None:
    ref, _ = pair
    assert ape_translation(ref, ref).max == 0.0
    assert rpe_translation(ref, ref).max == pytest.approx(0.0, abs=1e-12)


def test_no_matching_stamps_is_an_error(pair) -> None:
    ref, est = pair
    late = Trajectory(est.stamps_ns + 10**12, est.poses)
    with pytest.raises(BagtoolsError, match="no pose of one trajectory has a pose of the other within 0.01 s"):
        ape_translation(ref, late)


def test_too_short_for_rpe_is_an_error(pair) -> None:
    ref, _ = pair
    short = Trajectory(ref.stamps_ns[:5], ref.poses[:5])
    with pytest.raises(BagtoolsError, match="travels less than"):
        rpe_translation(short, short, delta_m=1.0)


def test_unsorted_stamps_are_an_error(pair) -> None:
    ref, est = pair
    shuffled = Trajectory(est.stamps_ns[::-1].copy(), est.poses[::-1].copy())
    with pytest.raises(BagtoolsError, match="not sorted"):
        associate(ref, shuffled)
