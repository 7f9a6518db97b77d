"""TUM trajectory files: round trip, precision, bad files."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from bagtools.errors import BagtoolsError
from bagtools.trajectory import Trajectory, read_tum, write_tum
from bagtools.transforms import pose2tform


def test_round_trip_keeps_ns_stamps_and_poses(tmp_path: Path) -> None:
    stamps = np.array([1_700_000_000_000_000_001, 1_700_000_000_200_000_000], dtype=np.int64)
    traj = Trajectory(stamps, pose2tform(np.array([[1.0, -2.0, 0.3], [1.5, -2.5, -3.0]])))
    write_tum(tmp_path / "t.tum", traj)
    back = read_tum(tmp_path / "t.tum")
    assert back.stamps_ns.tolist() == stamps.tolist()
    np.testing.assert_allclose(back.poses, traj.poses, atol=1e-8)
    first = (tmp_path / "t.tum").read_text().splitlines()[0].split()
    assert first[0] == "1700000000.000000001" and len(first) == 8


def test_evo_reads_our_files(tmp_path: Path) -> None:
    file_interface = pytest.importorskip("evo.tools.file_interface")
    traj = Trajectory(np.array([10**9, 2 * 10**9]), pose2tform(np.array([[0.0, 0.0, 0.0], [1.0, 0.5, 0.2]])))
    write_tum(tmp_path / "t.tum", traj)
    evo_traj = file_interface.read_tum_trajectory_file(str(tmp_path / "t.tum"))
    np.testing.assert_allclose(evo_traj.positions_xyz, traj.positions, atol=1e-9)
    np.testing.assert_allclose(evo_traj.timestamps, [1.0, 2.0])


@pytest.mark.parametrize("content,problem", [
    ("1.0 0 0 0 0 0 0\n", "expected 8 values"),
    ("1.0 0 0 0 0 0 0 x\n", "not a number"),
    ("1.0 0 0 0 0 0 0 2\n", "norm"),
    ("# only a comment\n", "holds no poses"),
])
def test_bad_files(tmp_path: Path, content: str, problem: str) -> None:
    path = tmp_path / "bad.tum"
    path.write_text(content)
    with pytest.raises(BagtoolsError, match=problem):
        read_tum(path)
    with pytest.raises(BagtoolsError, match="no such trajectory file"):
        read_tum(tmp_path / "missing.tum")
