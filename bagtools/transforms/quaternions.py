"""Quaternions, scalar first [w x y z] as in MATLAB, and their conversions (MATLAB names).

Shapes: quat (4,) or (N,4) [w x y z]; rotm (3,3)/(N,3,3); tform (4,4)/(N,4,4);
eul (3,)/(N,3) radians in the order of ``seq``; axang (4,)/(N,4) [x y z theta];
points (3,)/(N,3). Conversions to a rotation normalize the quaternion first (as
MATLAB); ``quatmultiply`` and ``quatconj`` are plain algebra on any quaternion.
At the ROS boundary (x, y, z, w) use :func:`xyzw2quat` and :func:`quat2xyzw`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from bagtools.transforms.checks import (
    as_stack,
    check_nonzero,
    check_rotations,
    check_same_count,
    check_seq,
    check_tforms,
)
from bagtools.transforms.rotations import rotations_to_eul, rotations_to_tforms, unstack

if TYPE_CHECKING:
    from scipy.spatial.transform import Rotation

# MATLAB's zero-angle threshold in quat2axang: |theta| below this gives the axis [0 0 1].
_ZERO_ANGLE_TOL = 10 * np.finfo(np.float64).eps


def wxyz_to_rotation(quat: np.ndarray) -> Rotation:
    """(N,4) nonzero [w x y z] quaternions -> scipy Rotation (scipy normalizes them)."""
    from scipy.spatial.transform import Rotation

    return Rotation.from_quat(quat[:, [1, 2, 3, 0]])


def rotation_to_wxyz(rotation: Rotation) -> np.ndarray:
    """scipy Rotation -> (N,4) unit [w x y z] quaternions with w >= 0 (scipy's canonical sign)."""
    return np.atleast_2d(rotation.as_quat(canonical=True))[:, [3, 0, 1, 2]]


def quats_to_axang(quat: np.ndarray) -> np.ndarray:
    """(N,4) nonzero [w x y z] -> (N,4) axis-angle [x y z theta], unit axis, theta in [-pi, pi] (no checks).

    As MATLAB: theta is 2*acos(w) of the normalized quaternion wrapped to [-pi, pi]
    (a quaternion with w < 0 gives a negative angle about the same axis), and a
    zero rotation gives [0 0 1 0].
    """
    vector = quat[:, 1:]
    vector_norm = np.sqrt(np.einsum("ni,ni->n", vector, vector))
    theta = 2.0 * np.arctan2(vector_norm, quat[:, 0])  # [0, 2pi]; scale-free, so no normalizing needed
    theta = np.where(theta > np.pi, theta - 2.0 * np.pi, theta)
    zero = np.abs(theta) < _ZERO_ANGLE_TOL
    axang = np.empty((len(quat), 4))
    safe_norm = np.where(zero, 1.0, vector_norm)
    axang[:, :3] = np.where(zero[:, None], [0.0, 0.0, 1.0], vector / safe_norm[:, None])
    axang[:, 3] = np.where(zero, 0.0, theta)
    return axang


def axang_to_quats(axang: np.ndarray, axis_norm: np.ndarray) -> np.ndarray:
    """(N,4) [x y z theta] with nonzero axes of norms ``axis_norm`` -> (N,4) unit [w x y z] = [cos(theta/2), axis sin(theta/2)]."""
    half = 0.5 * axang[:, 3]
    quat = np.empty((len(axang), 4))
    quat[:, 0] = np.cos(half)
    quat[:, 1:] = axang[:, :3] * (np.sin(half) / axis_norm)[:, None]
    return quat


def _quat_stack(quat: np.ndarray, name: str = "quat") -> tuple[np.ndarray, bool]:
    quat_arr, single = as_stack(quat, name, (4,))
    check_nonzero(quat_arr, name, single, "quaternion")
    return quat_arr, single


def xyzw2quat(quat_xyzw: np.ndarray) -> np.ndarray:
    """ROS-order quaternion [x y z w] (4,)/(N,4) -> scalar-first [w x y z] (4,)/(N,4); no normalizing."""
    quat_arr, single = as_stack(quat_xyzw, "quat_xyzw", (4,))
    return unstack(quat_arr[:, [3, 0, 1, 2]], single)


def quat2xyzw(quat: np.ndarray) -> np.ndarray:
    """Scalar-first quaternion [w x y z] (4,)/(N,4) -> ROS order [x y z w] (4,)/(N,4); no normalizing."""
    quat_arr, single = as_stack(quat, "quat", (4,))
    return unstack(quat_arr[:, [1, 2, 3, 0]], single)


def quat2rotm(quat: np.ndarray) -> np.ndarray:
    """Quaternion [w x y z] (4,)/(N,4), normalized first -> rotation matrix (3,3)/(N,3,3)."""
    quat_arr, single = _quat_stack(quat)
    return unstack(wxyz_to_rotation(quat_arr).as_matrix(), single)


def rotm2quat(rotm: np.ndarray) -> np.ndarray:
    """Rotation matrix (3,3)/(N,3,3) -> unit quaternion [w x y z] (4,)/(N,4) with w >= 0.

    For a 180-degree rotation (w = 0) the first nonzero of x, y, z is positive.
    """
    from scipy.spatial.transform import Rotation

    rotm_arr, single = as_stack(rotm, "rotm", (3, 3))
    check_rotations(rotm_arr, "rotm", single)
    return unstack(rotation_to_wxyz(Rotation.from_matrix(rotm_arr)), single)


def quat2tform(quat: np.ndarray) -> np.ndarray:
    """Quaternion [w x y z] (4,)/(N,4), normalized first -> transform (4,4)/(N,4,4), zero translation."""
    quat_arr, single = _quat_stack(quat)
    return unstack(rotations_to_tforms(wxyz_to_rotation(quat_arr).as_matrix()), single)


def tform2quat(tform: np.ndarray) -> np.ndarray:
    """Transform (4,4)/(N,4,4) -> unit quaternion [w x y z] (4,)/(N,4) of its rotation, w >= 0."""
    from scipy.spatial.transform import Rotation

    tform_arr, single = as_stack(tform, "tform", (4, 4))
    check_tforms(tform_arr, "tform", single)
    return unstack(rotation_to_wxyz(Rotation.from_matrix(tform_arr[:, :3, :3])), single)


def eul2quat(eul: np.ndarray, seq: str = "ZYX") -> np.ndarray:
    """Euler angles (3,)/(N,3), radians, intrinsic ``seq`` -> unit quaternion [w x y z] (4,)/(N,4).

    The quaternion is the Hamilton product of the three elementary half-angle
    quaternions (as MATLAB), so w may be negative.
    """
    from scipy.spatial.transform import Rotation

    seq = check_seq(seq)
    eul_arr, single = as_stack(eul, "eul", (3,))
    quat_xyzw = np.atleast_2d(Rotation.from_euler(seq, eul_arr).as_quat())
    return unstack(quat_xyzw[:, [3, 0, 1, 2]], single)


def quat2eul(quat: np.ndarray, seq: str = "ZYX") -> np.ndarray:
    """Quaternion [w x y z] (4,)/(N,4), normalized first -> Euler angles (3,)/(N,3), radians, order of ``seq``.

    Goes through the rotation matrix, so angle ranges and gimbal-lock handling
    are exactly those of :func:`bagtools.transforms.rotm2eul`.
    """
    seq = check_seq(seq)
    quat_arr, single = _quat_stack(quat)
    return unstack(rotations_to_eul(wxyz_to_rotation(quat_arr).as_matrix(), seq), single)


def axang2quat(axang: np.ndarray) -> np.ndarray:
    """Axis-angle [x y z theta] (4,)/(N,4), theta in radians, axis normalized first -> unit quaternion [w x y z]."""
    axang_arr, single = as_stack(axang, "axang", (4,))
    axis_norm = check_nonzero(axang_arr[:, :3], "axang", single, "rotation axis")
    return unstack(axang_to_quats(axang_arr, axis_norm), single)


def quat2axang(quat: np.ndarray) -> np.ndarray:
    """Quaternion [w x y z] (4,)/(N,4), normalized first -> axis-angle [x y z theta] (4,)/(N,4).

    Unit axis; theta in [-pi, pi] radians (negative when w < 0, as MATLAB); the
    identity gives [0 0 1 0].
    """
    quat_arr, single = _quat_stack(quat)
    return unstack(quats_to_axang(quat_arr), single)


def quatmultiply(quat_a: np.ndarray, quat_b: np.ndarray) -> np.ndarray:
    """Hamilton product a * b of [w x y z] quaternions (4,)/(N,4) each; one item pairs with every item of the other.

    Not normalized. For unit quaternions, quat2rotm(a * b) = quat2rotm(a) @ quat2rotm(b):
    rotate by b first, then by a.
    """
    a, single_a = as_stack(quat_a, "quat_a", (4,))
    b, single_b = as_stack(quat_b, "quat_b", (4,))
    check_same_count(len(a), "quat_a", len(b), "quat_b")
    aw, ax, ay, az = a.T
    bw, bx, by, bz = b.T
    product = np.stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ],
        axis=-1,
    )
    return unstack(product, single_a and single_b)


def quatconj(quat: np.ndarray) -> np.ndarray:
    """Conjugate [w -x -y -z] of quaternions [w x y z] (4,)/(N,4); not normalized."""
    quat_arr, single = as_stack(quat, "quat", (4,))
    return unstack(quat_arr * np.array([1.0, -1.0, -1.0, -1.0]), single)


def quatinv(quat: np.ndarray) -> np.ndarray:
    """Inverse conj(q) / |q|^2 of nonzero quaternions [w x y z] (4,)/(N,4) (equals the conjugate for unit ones)."""
    quat_arr, single = _quat_stack(quat)
    norm_sq = np.einsum("ni,ni->n", quat_arr, quat_arr)
    return unstack(quat_arr * np.array([1.0, -1.0, -1.0, -1.0]) / norm_sq[:, None], single)


def rotatepoint(quat: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Rotate points (3,)/(N,3) by quaternions [w x y z] (4,)/(N,4), normalized first: p' = q p q^-1.

    One quaternion rotates every point, one point is rotated by every quaternion,
    or N quaternions pair with N points. Returns (3,) for one of each, else (N,3),
    in the units of ``points``.
    """
    quat_arr, single_q = _quat_stack(quat)
    points_arr, single_p = as_stack(points, "points", (3,))
    check_same_count(len(quat_arr), "quat", len(points_arr), "points")
    rotation = wxyz_to_rotation(quat_arr)
    if len(quat_arr) == 1:
        rotated = rotation[0].apply(points_arr)
    elif len(points_arr) == 1:
        rotated = rotation.apply(points_arr[0])
    else:
        rotated = rotation.apply(points_arr)
    return unstack(np.atleast_2d(rotated), single_q and single_p)
