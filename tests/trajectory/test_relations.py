"""Pose relations (Kuemmerle et al. 2009): reading .relations files and the relations metric."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from bagtools.errors import BagtoolsError
from bagtools.trajectory import (
    Relations, Trajectory, read_relations, relation_errors, relations_from_trajectory, relations_text,
)
from bagtools.transforms import pose2tform, se2_compose

T0_NS = 1_000_000_000_000_000_000


def _trajectory(poses: np.ndarray, step_ns: int = 100_000_000) -> Trajectory:
    poses = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
    return Trajectory(T0_NS + step_ns * np.arange(len(poses), dtype=np.int64), pose2tform(poses).reshape(-1, 4, 4))


def _path(n: int = 30) -> np.ndarray:
    """A curved planar path: 0.3 m steps turning 0.05 rad each."""
    poses = [np.zeros(3)]
    for _ in range(n - 1):
        poses.append(se2_compose(poses[-1], np.array([0.3, 0.0, 0.05])))
    return np.array(poses)


def test_reads_the_published_format_with_exact_stamps(tmp_path: Path) -> None:
    path = tmp_path / "log.relations"
    path.write_text("# a comment\n\n976052905.167303 976052911.885496 -0.056990 -0.128430 0.000000 0.000000 0.000000 "
                    "-1.682210\n976052896.784509 976052905.167303 -0.153130 -0.051420 0 0 0 -2.405850  # trailing\n")
    rel = read_relations(path)
    assert len(rel) == 2
    assert rel.first_ns.tolist() == [976052905_167303000, 976052896_784509000]
    assert rel.second_ns.tolist() == [976052911_885496000, 976052905_167303000]
    np.testing.assert_allclose(rel.motion, [[-0.05699, -0.12843, -1.68221], [-0.15313, -0.05142, -2.40585]])


def test_text_round_trip(tmp_path: Path) -> None:
    traj = _trajectory(_path())
    pairs = np.array([[0, 1], [3, 9], [20, 2]])
    rel = relations_from_trajectory(traj, pairs)
    (tmp_path / "r.relations").write_text(relations_text(rel))
    back = read_relations(tmp_path / "r.relations")
    assert back.first_ns.tolist() == traj.stamps_ns[pairs[:, 0]].tolist()
    assert back.second_ns.tolist() == traj.stamps_ns[pairs[:, 1]].tolist()
    np.testing.assert_allclose(back.motion, rel.motion, atol=1e-6)


def test_the_relations_of_a_part_of_the_log_lie_wholly_in_it() -> None:
    traj = _trajectory(_path())
    rel = relations_from_trajectory(traj, np.array([[0, 1], [3, 9], [20, 2], [12, 19], [19, 12], [15, 25]]))
    part = rel.within(int(traj.stamps_ns[10]), int(traj.stamps_ns[20]))
    assert list(zip(part.first_ns.tolist(), part.second_ns.tolist())) == [
        (int(traj.stamps_ns[12]), int(traj.stamps_ns[19])), (int(traj.stamps_ns[19]), int(traj.stamps_ns[12]))]
    np.testing.assert_array_equal(part.motion, rel.motion[3:5])
    assert len(rel.within(int(traj.stamps_ns[26]), int(traj.stamps_ns[29]))) == 0


def test_a_perfect_trajectory_scores_zero_and_a_known_error_is_measured() -> None:
    poses = _path()
    truth = _trajectory(poses)
    pairs = np.stack([np.arange(29), np.arange(1, 30)], axis=1)
    rel = relations_from_trajectory(truth, pairs)
    perfect = relation_errors(rel, truth)
    assert perfect["used"] == 29 and perfect["missing"] == 0
    assert perfect["trans_mean_m"] < 1e-12 and perfect["rot_mean_deg"] < 1e-9
    # Pose 10 displaced by 5 cm along its own y axis: the relations 9->10 and 10->11 see it, the others do not.
    moved = poses.copy()
    moved[10] = se2_compose(poses[10], np.array([0.0, 0.05, 0.0]))
    scored = relation_errors(rel, _trajectory(moved))
    assert scored["trans_max_m"] == pytest.approx(0.05, abs=1e-9)
    assert scored["trans_mean_m"] == pytest.approx(2 * 0.05 / 29, rel=0.05)
    assert scored["rot_mean_deg"] < 1e-9
    # A heading error of 1 degree at pose 10 shows as 1 degree in both relations, and moves pose 11 as seen from 10.
    turned = poses.copy()
    turned[10, 2] += np.radians(1.0)
    scored = relation_errors(rel, _trajectory(turned))
    assert scored["rot_mean_deg"] == pytest.approx(2.0 / 29, rel=1e-6)
    assert scored["trans_max_m"] == pytest.approx(0.3 * np.radians(1.0), rel=0.01)


def test_relations_without_poses_are_counted_not_guessed() -> None:
    truth = _trajectory(_path())
    rel = relations_from_trajectory(truth, np.array([[0, 1], [1, 2]]))
    shifted = Relations(rel.first_ns + np.array([0, 50_000_000]), rel.second_ns, rel.motion)  # 50 ms off: no pose
    scored = relation_errors(shifted, truth)
    assert scored["relations"] == 2 and scored["used"] == 1 and scored["missing"] == 1
    later = Relations(rel.first_ns + 10**12, rel.second_ns + 10**12, rel.motion)
    none = relation_errors(later, truth)
    assert none["used"] == 0 and "trans_mean_m" not in none
    assert "the nearest pose is 997.100 s from a relation's stamp" in none["unavailable"], none["unavailable"]


def test_relations_whose_stamps_meet_one_pose_are_counted_not_scored_as_no_motion() -> None:
    """The Intel log's relations include pairs of stamps 6 ms apart for a 0.35 m motion: with evo's 0.01 s
    tolerance both meet the same scan, and scoring the relation against that pose's motion to itself (none)
    would add its whole length as error."""
    truth = _trajectory(_path())
    rel = relations_from_trajectory(truth, np.array([[0, 1], [4, 5]]))
    close = Relations(rel.first_ns, rel.second_ns.copy(), rel.motion)
    close.second_ns[1] = close.first_ns[1] + 6_000_000  # 6 ms after the first stamp: the same pose at 0.01 s
    scored = relation_errors(close, truth, max_diff_ns=10_000_000)
    assert scored["used"] == 1 and scored["same_pose"] == 1 and scored["missing"] == 0
    assert scored["trans_max_m"] < 1e-9
    only = relation_errors(Relations(close.first_ns[1:], close.second_ns[1:], close.motion[1:]), truth,
                           max_diff_ns=10_000_000)
    assert only["used"] == 0 and "both stamps at one pose" in only["unavailable"]


def test_a_relation_with_two_equal_stamps_is_counted_as_same_pose_not_scored() -> None:
    """A line whose two stamps are equal names no motion: scored, it would add its motion's length as error (or
    nothing for a zero motion, a free perfect relation)."""
    truth = _trajectory(_path())
    rel = relations_from_trajectory(truth, np.array([[0, 1], [2, 3]]))
    rel.second_ns[1] = rel.first_ns[1]
    scored = relation_errors(rel, truth)
    assert scored["used"] == 1 and scored["same_pose"] == 1 and scored["missing"] == 0


@pytest.mark.parametrize("kind", ["fifo", "directory", "device"])
def test_a_relations_path_that_is_not_a_regular_file_is_refused_before_reading(tmp_path: Path, kind: str) -> None:
    """A FIFO would block forever and /dev/zero read until memory runs out: regular files only."""
    import os

    path = {"fifo": tmp_path / "rel.fifo", "directory": tmp_path, "device": Path("/dev/zero")}[kind]
    if kind == "fifo":
        os.mkfifo(path)
    with pytest.raises(BagtoolsError, match="is not a regular file") as info:
        read_relations(path)
    assert info.value.path == str(path)


def test_a_relation_names_scans_by_their_exact_stamps() -> None:
    """A relation's stamp 3 ms from a pose names another scan of the log (the Intel log stamps scans in bursts,
    0.3 m apart for 3 ms): by default it is missing, not scored against the neighbouring pose; a stamp
    rounded through a float (within a microsecond) still meets its pose."""
    truth = _trajectory(_path())
    rel = relations_from_trajectory(truth, np.array([[0, 1], [2, 3], [4, 5]]))
    moved = Relations(rel.first_ns.copy(), rel.second_ns.copy(), rel.motion)
    moved.second_ns[1] += 3_000_000  # 3 ms off: another scan
    moved.first_ns[2] += 700  # float rounding of a stamp printed to the microsecond
    scored = relation_errors(moved, truth)
    assert scored["used"] == 2 and scored["missing"] == 1
    assert scored["trans_max_m"] < 1e-9
    assert relation_errors(moved, truth, max_diff_ns=10_000_000)["used"] == 3
    late = relation_errors(Relations(rel.first_ns + 3_000_000, rel.second_ns + 3_000_000, rel.motion), truth)
    assert late["used"] == 0 and "the nearest pose is 3.000 ms from a relation's stamp" in late["unavailable"]


@pytest.mark.parametrize("text,message", [
    ("", "holds no relation"),
    ("# only a comment\n", "holds no relation"),
    ("1.0 2.0 0.1 0.2 0 0 0\n", "line 1 has 7 fields, expected 8"),
    ("1.0 2.0 0.1 0.2 0 0 0 0.1\n1.0 2.0 x 0.2 0 0 0 0.1\n", "line 2 is not a relation"),
    ("-1.0 2.0 0.1 0.2 0 0 0 0.1\n", "line 1 is not a relation"),
    ("1.0 2.0 nan 0.2 0 0 0 0.1\n", "line 1 holds a value that is not finite"),
    ("1234567890123456789012345678901.0 2.0 0.1 0.2 0 0 0 0.1\n", "line 1 has a stamp outside 0 .. 9223372037 s"),
])
def test_bad_files_are_one_line_errors_naming_the_file(tmp_path: Path, text: str, message: str) -> None:
    path = tmp_path / "bad.relations"
    path.write_text(text)
    with pytest.raises(BagtoolsError, match=message) as err:
        read_relations(path)
    assert str(path) in str(err.value) and "\n" not in str(err.value)


def test_a_missing_file_names_it(tmp_path: Path) -> None:
    with pytest.raises(BagtoolsError, match="cannot read the relations file") as err:
        read_relations(tmp_path / "none.relations")
    assert "none.relations" in str(err.value)


def test_a_single_pose_trajectory_scores_nothing_and_says_why() -> None:
    one = _trajectory(np.zeros((1, 3)))
    rel = Relations(np.array([T0_NS + 5_000_000_000]), np.array([T0_NS + 6_000_000_000]), np.zeros((1, 3)))
    scored = relation_errors(rel, one)
    assert scored["used"] == 0 and "the nearest pose is 5.000 s" in scored["unavailable"]
