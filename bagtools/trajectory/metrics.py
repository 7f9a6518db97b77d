"""Trajectory errors with evo's definitions: absolute pose error (APE) and relative pose error (RPE).

Both are the translation part (evo's default ``-r trans_part``), in metres, with
no alignment (evo without ``-a``): express both trajectories in the same frame
first (e.g. anchor the reference at the estimate's first pose, as evo's
``--align_origin`` does). The statistics are evo's: rmse, mean, median, std
(population), min, max, sse.

- Association (evo ``sync.associate_trajectories``, nearest time): starting
  from the trajectory with fewer poses, each of its stamps is paired with the
  nearest stamp of the other within ``max_diff_ns`` (evo's ``--t_max_diff``,
  0.01 s by default); on a tie the earlier stamp wins.
- APE: ``|t_est_i - t_ref_i|`` over the associated pairs (``evo_ape tum ref est``).
- RPE per distance (``evo_rpe tum ref est --delta 1 --delta_unit m``): pose
  indices i_0 = 0 < i_1 < ... where each i_k is the first pose at which the path
  length of the *estimate* since i_(k-1) reaches ``delta_m`` (evo's consecutive
  pairs, pairs taken from the estimate); for each pair the error is the
  translation of ``inv(inv(Q_i) Q_j) inv(P_i) P_j`` (Q reference, P estimate).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bagtools.errors import BagtoolsError
from bagtools.trajectory.tum import Trajectory

#: evo's default ``--t_max_diff`` (0.01 s), in nanoseconds.
DEFAULT_MAX_DIFF_NS = 10_000_000


@dataclass(frozen=True)
class ErrorStats:
    """evo's statistics of an error vector (metres) and the number of errors."""

    rmse: float
    mean: float
    median: float
    std: float
    min: float
    max: float
    sse: float
    count: int

    @staticmethod
    def of(errors: np.ndarray) -> ErrorStats:
        """Statistics of a non-empty (N,) array of errors."""
        e = np.asarray(errors, dtype=np.float64)
        if e.size == 0:
            raise ValueError("no errors to summarize")
        sq = e * e
        return ErrorStats(rmse=float(np.sqrt(sq.mean())), mean=float(e.mean()), median=float(np.median(e)),
                          std=float(e.std()), min=float(e.min()), max=float(e.max()), sse=float(sq.sum()),
                          count=int(e.size))

    def as_dict(self) -> dict[str, float | int]:
        return {"rmse": self.rmse, "mean": self.mean, "median": self.median, "std": self.std, "min": self.min,
                "max": self.max, "sse": self.sse, "count": self.count}


def _nearest_within(short_ns: np.ndarray, long_ns: np.ndarray, max_diff_ns: int) -> tuple[np.ndarray, np.ndarray]:
    """Indices (into short, into long) of stamps of ``short`` with a stamp of sorted ``long`` within ``max_diff_ns``."""
    upper = np.minimum(np.searchsorted(long_ns, short_ns, side="right"), len(long_ns) - 1)
    lower = np.maximum(upper - 1, 0)
    diff_ub = long_ns[upper] - short_ns
    diff_lb = np.where(upper > 0, short_ns - long_ns[lower], np.iinfo(np.int64).max)
    take_upper = (diff_ub <= max_diff_ns) & (diff_ub >= 0) & (diff_ub < diff_lb)
    take_lower = ~take_upper & (diff_lb <= max_diff_ns) & (diff_lb >= 0) & ((diff_lb <= diff_ub) | (diff_ub < 0))
    keep = take_upper | take_lower
    return np.flatnonzero(keep), np.where(take_upper, upper, lower)[keep]


def _duration_text(ns: int) -> str:
    return f"{ns / 1e9:.3f} s" if ns >= 1_000_000_000 else f"{ns / 1e6:.3f} ms"


def associate(ref: Trajectory, est: Trajectory, max_diff_ns: int = DEFAULT_MAX_DIFF_NS) -> tuple[Trajectory, Trajectory]:
    """The pairs of poses of ``ref`` and ``est`` at matching stamps (evo's nearest-time association).

    Returns (ref', est') of equal length. Raises BagtoolsError when no stamps
    match or a trajectory's stamps are not sorted.
    """
    for name, traj in (("reference", ref), ("estimate", est)):
        if len(traj) == 0:
            raise BagtoolsError(f"the {name} trajectory is empty")
        if np.any(np.diff(traj.stamps_ns) < 0):
            raise BagtoolsError(f"the {name} trajectory's stamps are not sorted")
    est_longer = len(est) > len(ref)
    short, long_ = (ref, est) if est_longer else (est, ref)
    i_short, i_long = _nearest_within(short.stamps_ns, long_.stamps_ns, int(max_diff_ns))
    if i_short.size == 0:
        at = np.clip(np.searchsorted(long_.stamps_ns, short.stamps_ns), 1, max(len(long_) - 1, 1))
        gap_ns = np.minimum(np.abs(long_.stamps_ns[at] - short.stamps_ns),
                            np.abs(long_.stamps_ns[at - 1] - short.stamps_ns)).min()
        raise BagtoolsError(f"no pose of one trajectory has a pose of the other within {max_diff_ns / 1e9:g} s (the "
                            f"nearest stamps are {_duration_text(int(gap_ns))} apart; --t-max-diff sets the tolerance)")
    short_m = Trajectory(short.stamps_ns[i_short], short.poses[i_short])
    long_m = Trajectory(long_.stamps_ns[i_long], long_.poses[i_long])
    return (short_m, long_m) if est_longer else (long_m, short_m)


def ape_translation(ref: Trajectory, est: Trajectory, max_diff_ns: int = DEFAULT_MAX_DIFF_NS) -> ErrorStats:
    """APE, translation part, metres: as ``evo_ape tum ref.tum est.tum`` (no alignment)."""
    ref_m, est_m = associate(ref, est, max_diff_ns)
    return ErrorStats.of(np.linalg.norm(est_m.positions - ref_m.positions, axis=1))


def path_pairs(positions: np.ndarray, delta_m: float) -> np.ndarray:
    """(K,2) index pairs of consecutive poses whose path length apart first reaches ``delta_m`` (evo's rule).

    ``positions`` (N,3) metres. One Python step per pair (per ``delta_m`` of
    path), the search along the path is vectorized.
    """
    if not delta_m > 0:
        raise ValueError(f"delta_m must be positive, got {delta_m}")
    steps = np.linalg.norm(np.diff(positions, axis=0), axis=1)
    travelled = np.concatenate(([0.0], np.cumsum(steps)))
    n = len(travelled)
    ids = [0]
    while True:
        last = ids[-1]
        # The global cumulative sum finds the spot; the path is then re-summed from `last` as evo
        # accumulates it (sequentially from zero), so a pair exactly at delta_m is decided the same way.
        guess = int(np.searchsorted(travelled, travelled[last] + delta_m, side="left"))
        end = n if guess + 2 >= n else guess + 2
        local = np.cumsum(steps[last:end - 1])
        hit = np.flatnonzero(local >= delta_m)
        if hit.size == 0 and end < n:
            local = np.cumsum(steps[last:])
            hit = np.flatnonzero(local >= delta_m)
        if hit.size == 0:
            break
        ids.append(last + 1 + int(hit[0]))
    idx = np.array(ids)
    return np.column_stack((idx[:-1], idx[1:]))


def _relative(poses: np.ndarray, i: np.ndarray, j: np.ndarray) -> np.ndarray:
    """inv(poses[i]) @ poses[j] for rigid 4x4 poses, vectorized."""
    R_i, t_i = poses[i, :3, :3], poses[i, :3, 3]
    rel = np.zeros((len(i), 4, 4))
    rel[:, :3, :3] = np.einsum("nki,nkj->nij", R_i, poses[j, :3, :3])
    rel[:, :3, 3] = np.einsum("nki,nk->ni", R_i, poses[j, :3, 3] - t_i)
    rel[:, 3, 3] = 1.0
    return rel


def rpe_translation(ref: Trajectory, est: Trajectory, delta_m: float = 1.0,
                    max_diff_ns: int = DEFAULT_MAX_DIFF_NS) -> ErrorStats:
    """RPE, translation part over ``delta_m`` of path, metres: as ``evo_rpe tum ref est --delta 1 --delta_unit m``.

    Raises BagtoolsError when the estimate travels less than ``delta_m`` (evo: "empty index list").
    """
    ref_m, est_m = associate(ref, est, max_diff_ns)
    pairs = path_pairs(est_m.positions, delta_m)
    if len(pairs) == 0:
        raise BagtoolsError(f"the estimate travels less than {delta_m:g} m, so no relative pose pair exists")
    Q = _relative(ref_m.poses, pairs[:, 0], pairs[:, 1])
    P = _relative(est_m.poses, pairs[:, 0], pairs[:, 1])
    # translation of inv(Q) @ P = Q_R^T (P_t - Q_t)
    err = np.einsum("nki,nk->ni", Q[:, :3, :3], P[:, :3, 3] - Q[:, :3, 3])
    return ErrorStats.of(np.linalg.norm(err, axis=1))


def rpe_frames(ref: Trajectory, est: Trajectory, delta: int = 1,
               max_diff_ns: int = DEFAULT_MAX_DIFF_NS) -> tuple[np.ndarray, np.ndarray]:
    """RPE over every pair of poses ``delta`` apart: errors (K,) in translation (m) and rotation angle (degrees).

    As ``evo_rpe tum ref est --delta N --delta_unit f --all_pairs`` with ``-r
    trans_part`` and ``-r angle_deg``: for each associated pair (i, i + delta)
    the error is ``inv(inv(Q_i) Q_j) inv(P_i) P_j``. With delta 1 it is the
    error of each step between consecutive scans. Raises BagtoolsError when
    fewer than ``delta + 1`` poses associate.
    """
    if delta < 1:
        raise ValueError(f"delta must be a positive number of poses, got {delta}")
    ref_m, est_m = associate(ref, est, max_diff_ns)
    n = len(est_m)
    if n <= delta:
        raise BagtoolsError(f"only {n} poses associate with the reference, fewer than {delta + 1}")
    i = np.arange(n - delta)
    Q = _relative(ref_m.poses, i, i + delta)
    P = _relative(est_m.poses, i, i + delta)
    R_err = np.einsum("nki,nkj->nij", Q[:, :3, :3], P[:, :3, :3])
    t_err = np.einsum("nki,nk->ni", Q[:, :3, :3], P[:, :3, 3] - Q[:, :3, 3])
    cos = np.clip((np.trace(R_err, axis1=1, axis2=2) - 1.0) / 2.0, -1.0, 1.0)
    return np.linalg.norm(t_err, axis=1), np.degrees(np.arccos(cos))
