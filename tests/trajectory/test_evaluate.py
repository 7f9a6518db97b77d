"""Trajectory errors: the SE(2) alignment equals evo's Umeyama, gap errors as step_error.py defines them."""

from __future__ import annotations

import numpy as np
import pytest
from evo.core.geometry import umeyama_alignment

from bagtools.errors import BagtoolsError
from bagtools.trajectory.evaluate import align_se2, ape_aligned, gap_errors, trajectory_errors
from bagtools.trajectory import Trajectory
from bagtools.transforms import pose2tform, se2_compose


def _trajectory(poses_xyt: np.ndarray, t0_ns: int = 1_000_000_000) -> Trajectory:
    stamps = t0_ns + np.arange(len(poses_xyt), dtype=np.int64) * 100_000_000
    return Trajectory(stamps, pose2tform(poses_xyt).reshape(-1, 4, 4))


def _path(n: int = 200, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    poses = [np.zeros(3)]
    for _ in range(n - 1):
        poses.append(se2_compose(poses[-1], [0.2, 0.0, rng.normal(0, 0.1)]))
    return np.array(poses)


def test_align_se2_equals_evo_umeyama_without_scale() -> None:
    rng = np.random.default_rng(1)
    P = rng.normal(0, 5, (50, 2))
    Q = P @ np.array([[np.cos(2.0), -np.sin(2.0)], [np.sin(2.0), np.cos(2.0)]]).T + [3.0, -1.0] + rng.normal(0, 0.1, (50, 2))
    R, t = align_se2(P, Q)
    R_evo, t_evo, _ = umeyama_alignment(np.vstack([P.T, np.zeros(50)]), np.vstack([Q.T, np.zeros(50)]), False)
    assert np.allclose(R, R_evo[:2, :2], atol=1e-9) and np.allclose(t, t_evo[:2], atol=1e-9)
    assert np.isclose(np.linalg.det(R), 1.0)


def test_aligned_ape_ignores_a_rigid_motion_and_measures_the_rest() -> None:
    truth = _path()
    moved = np.array([se2_compose([4.0, -2.0, 1.0], p) for p in truth])
    assert ape_aligned(_trajectory(truth), _trajectory(moved)).rmse < 1e-9
    bent = moved.copy()
    bent[100:, :2] += [0.3, 0.0]
    stats = ape_aligned(_trajectory(truth), _trajectory(bent))
    assert 0.05 < stats.rmse < 0.3


def test_gap_errors_by_hand() -> None:
    truth = _path(50)
    est = truth.copy()
    est[30:, :2] += [0.1, 0.0]  # one step error of 10 cm between poses 29 and 30
    one = gap_errors(_trajectory(truth), _trajectory(est), 1)
    assert one["pairs"] == 49 and np.isclose(one["trans_max_m"], 0.1) and np.isclose(one["trans_mean_m"], 0.1 / 49)
    twenty = gap_errors(_trajectory(truth), _trajectory(est), 20)
    assert twenty["pairs"] == 30 and np.isclose(twenty["trans_mean_m"], 20 * 0.1 / 30)
    with pytest.raises(BagtoolsError):
        gap_errors(_trajectory(truth[:10]), _trajectory(est[:10]), 20)


def test_trajectory_errors_say_why_an_error_is_missing() -> None:
    truth = _path(10)
    errors = trajectory_errors(_trajectory(truth), _trajectory(truth))
    assert errors["ape_aligned_m"]["rmse"] < 1e-9 and errors["relative_gap_1"]["trans_mean_m"] < 1e-9
    assert "unavailable" in errors["relative_gap_20"]
    late = trajectory_errors(_trajectory(truth), _trajectory(truth, t0_ns=9_000_000_000))
    assert all("unavailable" in v for v in late.values())
