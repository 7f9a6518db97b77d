"""Pose relations and the relations metric of R. Kümmerle et al., "On measuring the accuracy of SLAM algorithms" (2009).

The classic 2D SLAM benchmarks (Intel Research Lab, Freiburg 079, MIT Killian
Court, ...) publish no trajectory: they publish *relations*, the motion between
two moments of the log, checked by hand, one per line of a ``.relations`` file::

    stamp_1 stamp_2 x y z roll pitch yaw

(stamps in seconds, the log's scan stamps; x, y, z in metres and roll, pitch,
yaw in radians: the pose at stamp_2 in the frame of the pose at stamp_1). The
metric compares each relation delta* with the estimate's motion delta between
the same stamps: the error is delta* ⊖ delta (``(delta*)^-1 delta``), and the
score is the mean of its translation (m) with its standard deviation, and of
its rotation (deg), over the relations; the paper also gives the means of the
squares. Planar: z, roll and pitch are read and ignored.

A relation names two scans of the log by their stamps (printed to the
microsecond), so it is scored only where the estimate has a pose at those very
stamps: within ``RELATION_MAX_DIFF_NS`` (0.1 ms), not evo's 0.01 s. A scan a
few milliseconds away is another scan of the log, and not necessarily a nearby
one: the Intel log stamps some scans in bursts, and its relations hold two
motions 0.32 m apart between stamps 6 ms apart. A relation without such poses
is left out and counted as missing.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from bagtools.errors import BagtoolsError
from bagtools.trajectory.metrics import _nearest_within
from bagtools.trajectory.tum import Trajectory, _stamp_ns
from bagtools.transforms import se2_between, tform2pose

#: Fields of a relation line.
RELATION_FIELDS = 8
#: A pose of the estimate is at a relation's stamp when it is this close (ns): the stamp's printed microseconds
#: and a float's rounding of them, well below the milliseconds between two scans of a log.
RELATION_MAX_DIFF_NS = 100_000
_MAX_STAMP_NS = int(np.iinfo(np.int64).max)


@dataclass(frozen=True)
class Relations:
    """Relations of a log: ``first_ns``, ``second_ns`` (K,) int64 stamps; ``motion`` (K,3) [x, y, yaw]
    (m, m, rad) of the pose at the second stamp in the frame of the pose at the first."""

    first_ns: np.ndarray
    second_ns: np.ndarray
    motion: np.ndarray

    def __len__(self) -> int:
        return int(self.first_ns.shape[0])

    def within(self, first_ns: int, last_ns: int) -> Relations:
        """The relations whose two stamps both lie in [first_ns, last_ns] (a part of the log)."""
        inside = ((self.first_ns >= first_ns) & (self.first_ns <= last_ns) & (self.second_ns >= first_ns)
                  & (self.second_ns <= last_ns))
        return Relations(self.first_ns[inside], self.second_ns[inside], self.motion[inside])


def read_relations(path: str | Path) -> Relations:
    """Read a ``.relations`` file (see the module docstring); blank lines and ``#`` comments are skipped.

    Raises:
        BagtoolsError: the file is not a regular file (a FIFO would block, a device never end) or cannot be
            read, a line is not 8 numbers or has a stamp beyond int64 nanoseconds, or it holds no relation.
    """
    path = Path(path)
    if path.exists() and not path.is_file():
        raise BagtoolsError("is not a regular file (a relations file is text: stamp_1 stamp_2 x y z roll pitch yaw)",
                            path)
    try:
        text = path.read_text(errors="replace")
    except OSError as err:
        raise BagtoolsError(f"cannot read the relations file: {err.strerror or err}", path) from err
    first, second, motion = [], [], []
    for number, line in enumerate(text.splitlines(), start=1):
        fields = line.split("#", 1)[0].split()
        if not fields:
            continue
        if len(fields) != RELATION_FIELDS:
            raise BagtoolsError(f"line {number} has {len(fields)} fields, expected {RELATION_FIELDS}: "
                                "stamp_1 stamp_2 x y z roll pitch yaw", path)
        try:
            t1, t2 = _stamp_ns(fields[0]), _stamp_ns(fields[1])
            values = [float(v) for v in fields[2:]]
        except ValueError as err:
            raise BagtoolsError(f"line {number} is not a relation ({err}): stamp_1 stamp_2 x y z roll pitch yaw",
                                path) from None
        if not all(np.isfinite(values)):
            raise BagtoolsError(f"line {number} holds a value that is not finite", path)
        if not all(0 <= t <= _MAX_STAMP_NS for t in (t1, t2)):
            raise BagtoolsError(f"line {number} has a stamp outside 0 .. {_MAX_STAMP_NS / 1e9:.0f} s", path)
        first.append(t1)
        second.append(t2)
        motion.append((values[0], values[1], values[5]))
    if not first:
        raise BagtoolsError("holds no relation (expected lines of: stamp_1 stamp_2 x y z roll pitch yaw)", path)
    return Relations(np.array(first, dtype=np.int64), np.array(second, dtype=np.int64),
                     np.array(motion, dtype=np.float64).reshape(-1, 3))


def relations_text(relations: Relations) -> str:
    """The lines of a ``.relations`` file (z, roll and pitch written as 0)."""
    lines = []
    for t1, t2, (x, y, yaw) in zip(relations.first_ns, relations.second_ns, relations.motion):
        stamps = " ".join(f"{int(t) // 1_000_000_000}.{int(t) % 1_000_000_000:09d}" for t in (t1, t2))
        lines.append(f"{stamps} {x:.6f} {y:.6f} 0.000000 0.000000 0.000000 {yaw:.6f}")
    return "\n".join(lines) + ("\n" if lines else "")


def relations_from_trajectory(trajectory: Trajectory, pairs: np.ndarray) -> Relations:
    """The relations of ``trajectory`` between its poses ``pairs`` (M,2) of indices (e.g. from a reference)."""
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    poses = tform2pose(trajectory.poses).reshape(-1, 3)
    return Relations(trajectory.stamps_ns[pairs[:, 0]], trajectory.stamps_ns[pairs[:, 1]],
                     se2_between(poses[pairs[:, 0]], poses[pairs[:, 1]]).reshape(-1, 3))


def relation_errors(relations: Relations, estimate: Trajectory, max_diff_ns: int = RELATION_MAX_DIFF_NS) -> dict:
    """The relations metric of ``estimate`` (see the module docstring) as a dict for summary.json.

    Keys: ``relations`` (in the file), ``max_diff_s`` (the association's
    tolerance), ``used``, ``missing`` (no pose at a stamp), ``same_pose``
    (both stamps at one pose: closer together than
    ``max_diff_ns``, which a wider tolerance meets in the Intel log, 6 ms
    apart for a 0.35 m motion; scoring them would score the relation against
    no motion),
    ``trans_mean_m``, ``trans_std_m``, ``trans_sq_mean_m2``,
    ``trans_max_m``, ``rot_mean_deg``, ``rot_std_deg``, ``rot_sq_mean_deg2``;
    with no relation usable, only the counts and ``unavailable``.
    """
    out: dict = {"relations": len(relations), "max_diff_s": max_diff_ns / 1e9}
    if len(estimate) == 0 or np.any(np.diff(estimate.stamps_ns) < 0):
        return {**out, "used": 0, "missing": len(relations), "unavailable": "the trajectory is empty or not sorted"}
    i1, j1 = _nearest_within(relations.first_ns, estimate.stamps_ns, int(max_diff_ns))
    i2, j2 = _nearest_within(relations.second_ns, estimate.stamps_ns, int(max_diff_ns))
    at1 = np.full(len(relations), -1, dtype=np.int64)
    at2 = np.full(len(relations), -1, dtype=np.int64)
    at1[i1], at2[i2] = j1, j2
    found = (at1 >= 0) & (at2 >= 0)
    same = found & (at1 == at2)  # equal stamps too: a relation of no motion scores nothing
    ok = found & ~same
    out.update(used=int(ok.sum()), missing=int((~found).sum()), same_pose=int(same.sum()))
    if found.any() and not ok.any():
        return {**out, "unavailable": "every relation found has both stamps at one pose of the trajectory"}
    if not ok.any():
        stamps = np.concatenate([relations.first_ns, relations.second_ns])
        at = np.searchsorted(estimate.stamps_ns, stamps)
        above, below = (estimate.stamps_ns[np.clip(i, 0, len(estimate) - 1)] for i in (at, at - 1))
        gap_ns = np.minimum(np.abs(above - stamps), np.abs(below - stamps))
        nearest_s = gap_ns.min() / 1e9
        nearest = f"{nearest_s:.3f} s" if nearest_s >= 1.0 else f"{nearest_s * 1e3:.3f} ms"
        return {**out, "unavailable": f"no relation has poses of the trajectory at both stamps (within "
                                      f"{max_diff_ns / 1e9:g} s; the nearest pose is {nearest} "
                                      "from a relation's stamp: were the scans stamped with another clock?)"}
    poses = tform2pose(estimate.poses).reshape(-1, 3)
    moved = se2_between(poses[at1[ok]], poses[at2[ok]]).reshape(-1, 3)
    error = se2_between(relations.motion[ok], moved).reshape(-1, 3)
    trans = np.hypot(error[:, 0], error[:, 1])
    rot = np.degrees(np.abs(error[:, 2]))
    return {**out, "trans_mean_m": float(trans.mean()), "trans_std_m": float(trans.std()),
            "trans_sq_mean_m2": float((trans**2).mean()), "trans_max_m": float(trans.max()),
            "rot_mean_deg": float(rot.mean()), "rot_std_deg": float(rot.std()),
            "rot_sq_mean_deg2": float((rot**2).mean())}


__all__ = ["RELATION_MAX_DIFF_NS", "Relations", "read_relations", "relation_errors", "relations_from_trajectory",
           "relations_text"]
