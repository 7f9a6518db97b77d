"""``bagtools eval``: a trajectory's APE, RPE and per-step error (equal to evo's), and the relations metric."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from evo.core import metrics, sync
from evo.core.trajectory import PoseTrajectory3D

from bagtools.trajectory import Trajectory, relations_from_trajectory, relations_text, write_tum
from bagtools.transforms import pose2tform
from tests.cli.test_data_loss import run

T0_NS = 1_700_000_000_000_000_000


@pytest.fixture
def files(tmp_path: Path) -> tuple[Path, Path, Trajectory, Trajectory]:
    """A planar reference (10 Hz, a curve) and an estimate that drifts from it, as TUM files."""
    rng = np.random.default_rng(5)
    n = 400
    yaw = np.cumsum(rng.normal(0.0, 0.03, n))
    xy = np.cumsum(0.1 * np.c_[np.cos(yaw), np.sin(yaw)], axis=0)
    stamps = T0_NS + np.arange(n, dtype=np.int64) * 100_000_000
    ref = Trajectory(stamps, pose2tform(np.c_[xy, yaw]))
    drift = np.c_[np.cumsum(rng.normal(0, 0.01, (n, 2)), axis=0), np.cumsum(rng.normal(0, 0.002, n))]
    est = Trajectory(stamps, pose2tform(np.c_[xy, yaw] + drift))
    write_tum(tmp_path / "ref.tum", ref)
    write_tum(tmp_path / "est.tum", est)
    return tmp_path / "est.tum", tmp_path / "ref.tum", est, ref


def _evo(traj: Trajectory) -> PoseTrajectory3D:
    return PoseTrajectory3D(poses_se3=list(traj.poses), timestamps=traj.stamps_ns / 1e9)


def test_ape_and_rpe_equal_evos(files, capsys) -> None:
    est_path, ref_path, est, ref = files
    code, out, err = run(["eval", str(est_path), str(ref_path), "--align", "--json"], capsys)
    assert code == 0, err
    result = json.loads(out)
    r, e = sync.associate_trajectories(_evo(ref), _evo(est), max_diff=0.01)
    ape = metrics.APE(metrics.PoseRelation.translation_part)
    ape.process_data((r, e))
    assert result["ape_translation_m"]["rmse"] == pytest.approx(ape.get_statistic(metrics.StatisticsType.rmse),
                                                                rel=1e-6)
    rpe = metrics.RPE(metrics.PoseRelation.translation_part, delta=1.0, delta_unit=metrics.Unit.meters,
                      all_pairs=False)
    rpe.process_data((r, e))
    assert result["rpe_translation_m_per_1m"]["mean"] == pytest.approx(rpe.get_statistic(metrics.StatisticsType.mean),
                                                                       rel=1e-6)
    e.align(r, correct_scale=False)  # evo_ape --align: Umeyama, no scale
    aligned = metrics.APE(metrics.PoseRelation.translation_part)
    aligned.process_data((r, e))
    assert result["ape_aligned_m"]["rmse"] == pytest.approx(aligned.get_statistic(metrics.StatisticsType.rmse),
                                                            rel=1e-6)
    assert result["relative_gap_1"]["pairs"] == 399 and result["relative_gap_1"]["over_0_2_m"] == 0


def test_the_text_report_and_the_gap(files, capsys) -> None:
    est_path, ref_path, _, _ = files
    code, out, err = run(["eval", str(est_path), str(ref_path), "--gap", "20"], capsys)
    assert code == 0 and err == "", err
    assert out.startswith("APE w.r.t. translation part (m), no alignment\n")
    assert "RPE w.r.t. translation part (m) for delta = 1 (m)" in out
    assert "error over 20 pose(s): mean " in out and "of 380 over 0.2 m" in out
    assert "after SE(2) alignment" not in out


def test_relations_at_exact_stamps(files, tmp_path: Path, capsys) -> None:
    est_path, _, est, ref = files
    relations = relations_from_trajectory(ref, np.array([[0, 50], [10, 200], [100, 399]]))
    (tmp_path / "log.relations").write_text(relations_text(relations))
    code, out, err = run(["eval", str(est_path), "--relations", str(tmp_path / "log.relations")], capsys)
    assert code == 0, err
    assert out.startswith("relations error ") and "over 3 of 3 relations" in out


@pytest.mark.parametrize("argv, problem", [
    (["{est}"], "give a REFERENCE trajectory, --relations FILE, or both"),
    (["{dir}/missing.tum", "{ref}"], "missing.tum: no such trajectory file"),
    (["{est}", "{ref}", "--gap", "0"], "invalid value for '--gap'"),
    (["{est}", "--relations", "{dir}/missing.relations"], "cannot read the relations file"),
    (["{dir}", "{ref}"], "is a directory, not a trajectory file"),
    (["/dev/zero", "{ref}"], "/dev/zero: is not a regular file (a pipe or a device)"),
    (["{est}", "{ref}", "--t-max-diff", "0"], "invalid value for '--t-max-diff'"),
])
def test_bad_input_is_one_line(argv: list[str], problem: str, files, tmp_path: Path, capsys) -> None:
    est_path, ref_path, _, _ = files
    args = [a.format(est=est_path, ref=ref_path, dir=tmp_path) for a in argv]
    code, out, err = run(["eval", *args], capsys)
    assert code == 2 and err.count("\n") == 1 and problem in err, err


def test_help_has_an_example(capsys) -> None:
    code, out, _ = run(["eval", "--help"], capsys)
    assert code == 0 and "Example:" in out and "bagtools eval" in out


def test_trajectories_that_never_pair_are_refused_with_the_offset(files, tmp_path: Path, capsys) -> None:
    """Stamps 20 ms apart (another clock): every figure was "unavailable" with exit 0; now exit 2 with the offset,
    and --t-max-diff pairs them (evo's --t_max_diff)."""
    est_path, _, est, ref = files
    write_tum(tmp_path / "late.tum", Trajectory(ref.stamps_ns + 20_000_000, ref.poses))
    code, out, err = run(["eval", str(est_path), str(tmp_path / "late.tum")], capsys)
    assert code == 2 and out == "" and err.count("\n") == 1, err
    assert "within 0.01 s (the nearest stamps are 20.000 ms apart; --t-max-diff sets the tolerance)" in err
    code, out, err = run(["eval", str(est_path), str(tmp_path / "late.tum"), "--t-max-diff", "0.03"], capsys)
    assert code == 0 and "pairs  400" in out, err


def test_relations_of_another_log_are_refused(files, tmp_path: Path, capsys) -> None:
    est_path, _, est, ref = files
    relations = relations_from_trajectory(Trajectory(ref.stamps_ns + 5_000_000_000_000, ref.poses),
                                          np.array([[0, 50], [10, 200]]))
    (tmp_path / "other.relations").write_text(relations_text(relations))
    code, out, err = run(["eval", str(est_path), "--relations", str(tmp_path / "other.relations")], capsys)
    assert code == 2 and err.count("\n") == 1 and "no relation has poses of the trajectory at both stamps" in err
