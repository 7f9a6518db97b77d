"""Errors of a planar trajectory against a reference: evo's APE and RPE, an SE(2)-aligned APE, errors over a gap.

- ``ape_translation_m``, ``rpe_translation_m_per_1m``: :mod:`bagtools.trajectory`'s
  (evo's definitions, no alignment: the reference is expressed in the
  estimate's frame, anchored at its first pose).
- ``ape_aligned_m``: translation APE after the rigid planar motion (rotation
  about z and translation, no scale) that best maps the estimate's positions
  onto the reference's in least squares (Umeyama's closed form in 2D, as
  ``evo_ape --align`` for planar data). It measures the shape of the
  trajectory, not where its start was put.
- ``relative_gap_<g>``: for every pair of associated poses g apart (poses, not
  metres), E = (ref_i^-1 ref_j)^-1 (est_i^-1 est_j); the mean, median and
  largest translation of E (m) and its mean rotation (deg). Gap 1 is the
  scan-to-scan error, larger gaps the drift over that many scans.
"""

from __future__ import annotations

import numpy as np

from bagtools.errors import BagtoolsError
from bagtools.trajectory import (
    ErrorStats, Relations, Trajectory, ape_translation, associate, relation_errors, rpe_frames, rpe_translation,
)
from bagtools.trajectory.metrics import DEFAULT_MAX_DIFF_NS
from bagtools.transforms import se2_between, tform2pose

#: Pose gaps reported by :func:`trajectory_errors`.
GAPS = (1, 20)


def align_se2(source_xy: np.ndarray, target_xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rotation R (2,2) and translation t (2,) minimizing sum |R p + t - q|^2 over pairs of (N,2) points (m)."""
    P = np.asarray(source_xy, dtype=np.float64).reshape(-1, 2)
    Q = np.asarray(target_xy, dtype=np.float64).reshape(-1, 2)
    if len(P) != len(Q) or len(P) < 2:
        raise ValueError(f"need two equally long sets of at least 2 points, got {len(P)} and {len(Q)}")
    mp, mq = P.mean(axis=0), Q.mean(axis=0)
    U, _, Vt = np.linalg.svd((Q - mq).T @ (P - mp))
    D = np.diag([1.0, np.sign(np.linalg.det(U @ Vt)) or 1.0])
    R = U @ D @ Vt
    return R, mq - R @ mp


def ape_aligned(reference: Trajectory, estimate: Trajectory, max_diff_ns: int = DEFAULT_MAX_DIFF_NS) -> ErrorStats:
    """Translation APE (m) after the best planar rigid alignment of the estimate onto the reference."""
    ref, est = associate(reference, estimate, max_diff_ns)
    if len(ref) < 2:
        raise BagtoolsError("fewer than two poses of the estimate match the reference's stamps")
    R, t = align_se2(est.positions[:, :2], ref.positions[:, :2])
    moved = est.positions[:, :2] @ R.T + t
    return ErrorStats.of(np.linalg.norm(moved - ref.positions[:, :2], axis=1))


def gap_errors(reference: Trajectory, estimate: Trajectory, gap: int, max_diff_ns: int = DEFAULT_MAX_DIFF_NS) -> dict:
    """Relative errors over pairs of associated poses ``gap`` apart (see the module docstring)."""
    ref, est = associate(reference, estimate, max_diff_ns)
    if len(ref) <= gap:
        raise BagtoolsError(f"fewer than {gap + 1} poses of the estimate match the reference's stamps")
    q, p = tform2pose(ref.poses), tform2pose(est.poses)
    err = se2_between(se2_between(q[:-gap], q[gap:]), se2_between(p[:-gap], p[gap:]))
    t = np.hypot(err[:, 0], err[:, 1])
    return {"gap_poses": gap, "pairs": int(len(t)), "trans_mean_m": float(t.mean()), "trans_median_m": float(np.median(t)),
            "trans_max_m": float(t.max()), "rot_mean_deg": float(np.degrees(np.abs(err[:, 2])).mean()),
            "over_0_2_m": int(np.count_nonzero(t > 0.2))}


def evaluate(estimate: Trajectory, reference: Trajectory | None, relations: Relations | None = None,
             gap: int = 1, align: bool = False, max_diff_ns: int | None = None) -> dict:
    """What ``bagtools eval`` reports of ``estimate``: against ``reference`` evo's APE (and, with ``align``, the
    APE after the best SE(2) alignment), evo's RPE per metre and the error over ``gap`` poses; against
    ``relations`` the metric of Kuemmerle et al. Poses pair within ``max_diff_ns`` (default: evo's 10 ms for
    trajectories, the relations' own tolerance for relations). Each part that cannot be computed says why."""
    out: dict = {"poses": len(estimate)}
    diff = DEFAULT_MAX_DIFF_NS if max_diff_ns is None else max_diff_ns
    if reference is not None:
        parts = [("ape_translation_m", lambda: ape_translation(reference, estimate, diff).as_dict()),
                 ("rpe_translation_m_per_1m", lambda: rpe_translation(reference, estimate, 1.0, diff).as_dict()),
                 (f"relative_gap_{gap}", lambda: gap_errors(reference, estimate, gap, diff))]
        if align:
            parts.insert(1, ("ape_aligned_m", lambda: ape_aligned(reference, estimate, diff).as_dict()))
        for name, fn in parts:
            try:
                out[name] = fn()
            except BagtoolsError as err:
                out[name] = {"unavailable": err.problem}
    if relations is not None:
        out["relations"] = (relation_errors(relations, estimate) if max_diff_ns is None
                            else relation_errors(relations, estimate, max_diff_ns))
    return out


def trajectory_errors(reference: Trajectory, estimate: Trajectory) -> dict:
    """Every error of the module docstring; one that cannot be computed says why."""
    out: dict = {}
    for name, fn in (("ape_translation_m", lambda: ape_translation(reference, estimate).as_dict()),
                     ("rpe_translation_m_per_1m", lambda: rpe_translation(reference, estimate, delta_m=1.0).as_dict()),
                     ("ape_aligned_m", lambda: ape_aligned(reference, estimate).as_dict())):
        try:
            out[name] = fn()
        except BagtoolsError as err:
            out[name] = {"unavailable": err.problem}
    for gap in GAPS:
        try:
            out[f"relative_gap_{gap}"] = gap_errors(reference, estimate, gap)
        except BagtoolsError as err:
            out[f"relative_gap_{gap}"] = {"unavailable": err.problem}
    return out


def odometry_errors(reference: Trajectory, estimate: Trajectory) -> dict:
    """An odometry's errors against ``reference`` (both in one frame, from one pose): APE, RPE per metre and per
    scan (translation m, rotation deg, and how many steps are off by more than 0.2 m); one that cannot be computed
    says why."""
    def per_scan() -> dict:
        trans, rot = rpe_frames(reference, estimate, delta=1)
        return {"translation_m": ErrorStats.of(trans).as_dict(), "rotation_deg": ErrorStats.of(rot).as_dict(),
                "steps_over_0_2m": int(np.count_nonzero(trans > 0.2))}

    out: dict = {}
    for name, fn in (("ape_translation_m", lambda: ape_translation(reference, estimate).as_dict()),
                     ("rpe_translation_m_per_1m", lambda: rpe_translation(reference, estimate, delta_m=1.0).as_dict()),
                     ("rpe_per_scan", per_scan)):
        try:
            out[name] = fn()
        except BagtoolsError as err:
            out[name] = {"unavailable": err.problem}
    return out
