"""Stamped pose trajectories and the TUM file format (``stamp x y z qx qy qz qw``, stamp in seconds).

TUM files are what evo reads (``evo_ape tum ref.tum est.tum``). Inside bagtools a
trajectory is int-nanosecond stamps and 4x4 poses ``T_frame_body``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from bagtools.errors import BagtoolsError
from bagtools.outputs import write_text_atomic
from bagtools.transforms import quat2tform, quat2xyzw, tform2quat, xyzw2quat


@dataclass(frozen=True)
class Trajectory:
    """Poses of a body in a fixed frame: ``stamps_ns`` (N,) int64, ``poses`` (N,4,4) T_frame_body."""

    stamps_ns: np.ndarray
    poses: np.ndarray

    def __post_init__(self) -> None:
        if self.poses.shape != (self.stamps_ns.shape[0], 4, 4):
            raise ValueError(f"poses must have shape ({self.stamps_ns.shape[0]},4,4), got {self.poses.shape}")

    def __len__(self) -> int:
        return int(self.stamps_ns.shape[0])

    @property
    def positions(self) -> np.ndarray:
        """(N,3) translations, metres."""
        return self.poses[:, :3, 3]

    @staticmethod
    def from_xyz_xyzw(stamps_ns: np.ndarray, xyz: np.ndarray, quat_xyzw: np.ndarray) -> Trajectory:
        """Build from (N,3) positions and (N,4) quaternions in ROS order x, y, z, w."""
        poses = quat2tform(xyzw2quat(np.asarray(quat_xyzw, dtype=np.float64).reshape(-1, 4)))
        poses[:, :3, 3] = np.asarray(xyz, dtype=np.float64).reshape(-1, 3)
        return Trajectory(np.asarray(stamps_ns, dtype=np.int64), poses)


def tum_text(trajectory: Trajectory) -> str:
    """The TUM lines of a trajectory (stamps in seconds with ns precision)."""
    quat_xyzw = quat2xyzw(tform2quat(trajectory.poses)) if len(trajectory) else np.empty((0, 4))
    lines = []
    for stamp_ns, xyz, q in zip(trajectory.stamps_ns, trajectory.positions, quat_xyzw):
        seconds = f"{int(stamp_ns) // 1_000_000_000}.{int(stamp_ns) % 1_000_000_000:09d}"
        lines.append(seconds + " " + " ".join(f"{v:.9f}" for v in (*xyz, *q)))
    return "\n".join(lines) + ("\n" if lines else "")


def write_tum(path: str | Path, trajectory: Trajectory, force: bool = False) -> Path:
    """Write ``trajectory`` as a TUM file, atomically."""
    return write_text_atomic(path, tum_text(trajectory), force)


def read_tum(path: str | Path) -> Trajectory:
    """Read a TUM file (comments with '#' allowed); raises BagtoolsError naming the file and line."""
    path = Path(path)
    if not path.is_file():
        raise BagtoolsError("no such trajectory file", path)
    stamps: list[int] = []
    rows: list[list[float]] = []
    for number, line in enumerate(path.read_text().splitlines(), start=1):
        text = line.split("#", 1)[0].strip()
        if not text:
            continue
        fields = text.replace(",", " ").split()
        if len(fields) != 8:
            raise BagtoolsError(f"line {number}: expected 8 values 'stamp x y z qx qy qz qw', got {len(fields)}", path)
        try:
            whole, _, frac = fields[0].partition(".")
            if whole.startswith("-"):
                raise ValueError(f"negative stamp {fields[0]}")
            stamps.append(int(whole or "0") * 1_000_000_000 + int((frac + "000000000")[:9]))
            rows.append([float(v) for v in fields[1:]])
        except ValueError as err:
            raise BagtoolsError(f"line {number}: not a number ({err})", path) from err
    if not rows:
        raise BagtoolsError("trajectory file holds no poses", path)
    values = np.array(rows)
    norms = np.linalg.norm(values[:, 3:], axis=1)
    if np.any(np.abs(norms - 1.0) > 1e-3):
        bad = int(np.flatnonzero(np.abs(norms - 1.0) > 1e-3)[0])
        raise BagtoolsError(f"pose {bad + 1} has a quaternion of norm {norms[bad]:.4f}, not 1", path)
    return Trajectory.from_xyz_xyzw(np.array(stamps, dtype=np.int64), values[:, :3], values[:, 3:])
