"""Stamped pose trajectories and the TUM file format (``stamp x y z qx qy qz qw``, stamp in seconds).

TUM files are what evo reads (``evo_ape tum ref.tum est.tum``). Inside bagtools a
trajectory is int-nanosecond stamps and 4x4 poses ``T_frame_body``.
"""

from __future__ import annotations

from array import array
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from bagtools.errors import BagtoolsError
from bagtools.outputs import write_text_atomic
from bagtools.stamps import seconds_text_to_ns
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


def tum_text(trajectory: Trajectory, frame: str | None = None, body: str | None = None) -> str:
    """The TUM lines of a trajectory (stamps in seconds with ns precision).

    With ``frame`` and ``body``, a first comment line ``# frame: F body: B``
    records which frame the poses are in and which robot frame they describe
    (evo and other TUM readers skip comments; :func:`read_tum_frames` reads it).
    """
    quat_xyzw = quat2xyzw(tform2quat(trajectory.poses)) if len(trajectory) else np.empty((0, 4))
    lines = [f"# frame: {frame} body: {body}"] if frame and body else []
    for stamp_ns, xyz, q in zip(trajectory.stamps_ns, trajectory.positions, quat_xyzw):
        seconds = f"{int(stamp_ns) // 1_000_000_000}.{int(stamp_ns) % 1_000_000_000:09d}"
        lines.append(seconds + " " + " ".join(f"{round(v, 9) + 0.0:.9f}" for v in (*xyz, *q)))  # never "-0.000000000"
    return "\n".join(lines) + ("\n" if lines else "")


def read_tum_frames(path: str | Path) -> tuple[str, str] | None:
    """(frame, body) from a TUM file's ``# frame: F body: B`` comment (as bagtools writes), or None."""
    try:
        with Path(path).open(encoding="utf-8", errors="replace") as f:
            for line in f:
                text = line.strip()
                if not text.startswith("#"):
                    return None
                words = text.lstrip("#").split()
                if len(words) == 4 and words[0] == "frame:" and words[2] == "body:":
                    return words[1], words[3]
    except OSError:
        return None
    return None


def write_tum(path: str | Path, trajectory: Trajectory, force: bool = False, frame: str | None = None,
              body: str | None = None) -> Path:
    """Write ``trajectory`` as a TUM file, atomically (with the frames comment when given)."""
    return write_text_atomic(path, tum_text(trajectory, frame, body), force)


#: Positions farther than this from the origin are damage, not a robot's path (metres).
MAX_TUM_COORDINATE_M = 1.0e6
#: Stamps after this (the year 2286) are damage, not a recording's clock (int ns).
MAX_TUM_STAMP_NS = 10_000_000_000 * 1_000_000_000


def read_tum(path: str | Path) -> Trajectory:
    """Read a TUM file (comments with '#' allowed); raises BagtoolsError naming the file and line.

    Refused: lines without 8 numbers, non-finite values, positions beyond
    :data:`MAX_TUM_COORDINATE_M`, stamps that are negative or beyond the year
    2286, quaternions that are not unit length, and stamps that go backwards
    or repeat.
    """
    path = Path(path)
    if not path.exists():
        raise BagtoolsError("no such trajectory file", path)
    if path.is_dir():
        raise BagtoolsError("is a directory, not a trajectory file", path)
    if not path.is_file():  # a FIFO, a device such as /dev/zero: not a file to read to its end
        raise BagtoolsError("is not a regular file (a pipe or a device), not a trajectory file", path)
    try:
        text_lines = path.read_text(encoding="utf-8").splitlines()
    except (UnicodeDecodeError, OSError) as err:
        raise BagtoolsError(f"not a TUM text file ({err.__class__.__name__})", path) from err
    stamps: array[int] = array("q")
    flat: array[float] = array("d")  # x y z qx qy qz qw of each pose, one after another
    numbers: array[int] = array("q")  # each pose's line number, for the messages
    for number, line in enumerate(text_lines, start=1):
        if "#" in line:
            line = line.split("#", 1)[0]
        fields = (line.replace(",", " ") if "," in line else line).split()
        if not fields:
            continue
        if len(fields) != 8:
            raise BagtoolsError(f"line {number}: expected 8 values 'stamp x y z qx qy qz qw', got {len(fields)}", path)
        try:
            stamps.append(_stamp_ns(fields[0]))
            flat.extend(map(float, fields[1:]))
        except (ValueError, OverflowError) as err:
            raise BagtoolsError(f"line {number}: not a number ({err})", path) from err
        numbers.append(number)
    del text_lines
    if not stamps:
        raise BagtoolsError("trajectory file holds no poses", path)
    values = np.frombuffer(flat, dtype=np.float64).reshape(-1, 7)
    stamps_ns = np.frombuffer(stamps, dtype=np.int64)
    with np.errstate(invalid="ignore"):
        bad = ~np.isfinite(values).all(axis=1) | (np.abs(values[:, :3]) > MAX_TUM_COORDINATE_M).any(axis=1)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise BagtoolsError(f"line {numbers[k]}: values must be finite, positions within {MAX_TUM_COORDINATE_M:g} m "
                            f"(got {' '.join(f'{v:g}' for v in values[k])})", path)
    late = np.flatnonzero(stamps_ns > MAX_TUM_STAMP_NS)
    if late.size:
        raise BagtoolsError(f"line {numbers[late[0]]}: stamp {stamps_ns[late[0]] / 1e9:.9f} s is past the year 2286 "
                            "(not a clock)", path)
    back = np.flatnonzero(np.diff(stamps_ns) <= 0)
    if back.size:
        k = int(back[0]) + 1
        raise BagtoolsError(f"line {numbers[k]}: stamp {stamps_ns[k] / 1e9:.9f} s is not after the previous one (time "
                            "going backwards or repeated)", path)
    norms = np.linalg.norm(values[:, 3:], axis=1)
    if np.any(np.abs(norms - 1.0) > 1e-3):
        bad_pose = int(np.flatnonzero(np.abs(norms - 1.0) > 1e-3)[0])
        raise BagtoolsError(f"pose {bad_pose + 1} has a quaternion of norm {norms[bad_pose]:.4f}, not 1", path)
    return Trajectory.from_xyz_xyzw(stamps_ns.copy(), values[:, :3], values[:, 3:])


def _stamp_ns(text: str) -> int:
    """A TUM stamp in seconds ('1700000000.123456789', '1.7e9') as int ns, exactly."""
    if text.startswith("-"):
        raise ValueError(f"negative stamp {text}")
    return seconds_text_to_ns(text)
