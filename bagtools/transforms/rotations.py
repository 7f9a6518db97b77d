"""Rotation matrices, homogeneous transforms, translation vectors and Euler angles (MATLAB names).

Shapes: rotm (3,3) or (N,3,3); tform (4,4) or (N,4,4); trvec (3,) or (N,3) metres;
eul (3,) or (N,3) radians, in the order of ``seq``. One item in, one item out;
a stack in, a stack out.
"""

from __future__ import annotations

import numpy as np

from bagtools.transforms.checks import as_stack, check_rotations, check_seq, check_tforms

# MATLAB's gimbal-lock threshold: the cosine (or sine, for ZYZ) of the middle angle below 10 * eps.
_GIMBAL_LOCK_TOL = 10 * np.finfo(np.float64).eps


def unstack(stack: np.ndarray, single: bool) -> np.ndarray:
    """Return item 0 of ``stack`` when the caller gave one item, else the whole stack."""
    return stack[0] if single else stack


def rotations_to_tforms(rotm: np.ndarray, trvec: np.ndarray | None = None) -> np.ndarray:
    """(N,3,3) rotations and optional (N,3) translations in metres -> (N,4,4) transforms (no checks)."""
    tform = np.zeros((len(rotm), 4, 4))
    tform[:, :3, :3] = rotm
    if trvec is not None:
        tform[:, :3, 3] = trvec
    tform[:, 3, 3] = 1.0
    return tform


def trvec2tform(trvec: np.ndarray) -> np.ndarray:
    """Translation [x y z] (3,)/(N,3), metres -> pure translation transform (4,4)/(N,4,4)."""
    trvec_arr, single = as_stack(trvec, "trvec", (3,))
    return unstack(rotations_to_tforms(np.broadcast_to(np.eye(3), (len(trvec_arr), 3, 3)), trvec_arr), single)


def tform2trvec(tform: np.ndarray) -> np.ndarray:
    """Homogeneous transform (4,4)/(N,4,4) -> its translation [x y z] (3,)/(N,3), metres."""
    tform_arr, single = as_stack(tform, "tform", (4, 4))
    check_tforms(tform_arr, "tform", single)
    return unstack(tform_arr[:, :3, 3].copy(), single)


def rotm2tform(rotm: np.ndarray) -> np.ndarray:
    """Rotation matrix (3,3)/(N,3,3) -> transform (4,4)/(N,4,4) with zero translation."""
    rotm_arr, single = as_stack(rotm, "rotm", (3, 3))
    check_rotations(rotm_arr, "rotm", single)
    return unstack(rotations_to_tforms(rotm_arr), single)


def tform2rotm(tform: np.ndarray) -> np.ndarray:
    """Homogeneous transform (4,4)/(N,4,4) -> its rotation matrix (3,3)/(N,3,3); translation dropped."""
    tform_arr, single = as_stack(tform, "tform", (4, 4))
    check_tforms(tform_arr, "tform", single)
    return unstack(tform_arr[:, :3, :3].copy(), single)


def eul_to_rotations(eul: np.ndarray, seq: str) -> np.ndarray:
    """(N,3) Euler angles in radians, intrinsic ``seq`` (upper case) -> (N,3,3) rotations (no checks)."""
    from scipy.spatial.transform import Rotation

    return Rotation.from_euler(seq, eul).as_matrix()


def rotations_to_eul(rotm: np.ndarray, seq: str) -> np.ndarray:
    """(N,3,3) rotations -> (N,3) Euler angles for ``seq`` ('ZYX', 'ZYZ' or 'XYZ'), with MATLAB's ranges.

    Ranges: first and third angle in [-pi, pi]; middle angle in [-pi/2, pi/2] for
    'ZYX'/'XYZ' and in [-pi, 0] for 'ZYZ' (MATLAB's choice, e.g. Ry(pi/2) ->
    [-pi -pi/2 -pi]). At gimbal lock (cosine of the middle angle, or its sine
    for 'ZYZ', below 10 * eps) the first angle is set to 0 and the third carries
    the whole remaining rotation, as MATLAB does; scipy's ``as_euler`` zeroes the
    third angle instead and warns, which is why the extraction is written here.
    """
    r = rotm
    eul = np.empty((len(r), 3))
    if seq == "ZYX":  # R = Rz(a) Ry(b) Rx(c)
        cos_b = np.hypot(r[:, 0, 0], r[:, 1, 0])
        lock = cos_b < _GIMBAL_LOCK_TOL
        eul[:, 0] = np.where(lock, 0.0, np.arctan2(r[:, 1, 0], r[:, 0, 0]))
        eul[:, 1] = np.arctan2(-r[:, 2, 0], cos_b)
        eul[:, 2] = np.where(lock, np.arctan2(-r[:, 1, 2], r[:, 1, 1]), np.arctan2(r[:, 2, 1], r[:, 2, 2]))
    elif seq == "XYZ":  # R = Rx(a) Ry(b) Rz(c)
        cos_b = np.hypot(r[:, 2, 2], r[:, 1, 2])
        lock = cos_b < _GIMBAL_LOCK_TOL
        eul[:, 0] = np.where(lock, 0.0, np.arctan2(-r[:, 1, 2], r[:, 2, 2]))
        eul[:, 1] = np.arctan2(r[:, 0, 2], cos_b)
        eul[:, 2] = np.where(lock, np.arctan2(r[:, 1, 0], r[:, 1, 1]), np.arctan2(-r[:, 0, 1], r[:, 0, 0]))
    elif seq == "ZYZ":  # R = Rz(a) Ry(b) Rz(c), b in [-pi, 0]
        sin_b = np.hypot(r[:, 2, 1], r[:, 2, 0])
        lock = sin_b < _GIMBAL_LOCK_TOL
        eul[:, 0] = np.where(lock, 0.0, np.arctan2(-r[:, 1, 2], -r[:, 0, 2]))
        eul[:, 1] = -np.arctan2(sin_b, r[:, 2, 2])
        eul[:, 2] = np.where(lock, np.arctan2(r[:, 1, 0], r[:, 1, 1]), np.arctan2(-r[:, 2, 1], r[:, 2, 0]))
    else:
        raise ValueError(f"unknown Euler sequence {seq!r}")
    return eul + 0.0  # turns -0.0 into 0.0


def eul2rotm(eul: np.ndarray, seq: str = "ZYX") -> np.ndarray:
    """Euler angles (3,)/(N,3), radians, in the order of ``seq`` -> rotation matrix (3,3)/(N,3,3).

    Intrinsic, as MATLAB: ``eul2rotm([a b c], 'ZYX') = Rz(a) @ Ry(b) @ Rx(c)``.
    ``seq`` is 'ZYX' (default), 'ZYZ' or 'XYZ', case-insensitive.
    """
    seq = check_seq(seq)
    eul_arr, single = as_stack(eul, "eul", (3,))
    return unstack(eul_to_rotations(eul_arr, seq), single)


def rotm2eul(rotm: np.ndarray, seq: str = "ZYX") -> np.ndarray:
    """Rotation matrix (3,3)/(N,3,3) -> Euler angles (3,)/(N,3), radians, in the order of ``seq``.

    Angle ranges and gimbal lock as MATLAB: first and third angle in [-pi, pi];
    middle in [-pi/2, pi/2] ('ZYX', 'XYZ') or [-pi, 0] ('ZYZ'); at gimbal lock the
    first angle is 0 and the third holds the combined rotation.
    """
    seq = check_seq(seq)
    rotm_arr, single = as_stack(rotm, "rotm", (3, 3))
    check_rotations(rotm_arr, "rotm", single)
    return unstack(rotations_to_eul(rotm_arr, seq), single)


def eul2tform(eul: np.ndarray, seq: str = "ZYX") -> np.ndarray:
    """Euler angles (3,)/(N,3), radians, in the order of ``seq`` -> transform (4,4)/(N,4,4), zero translation."""
    seq = check_seq(seq)
    eul_arr, single = as_stack(eul, "eul", (3,))
    return unstack(rotations_to_tforms(eul_to_rotations(eul_arr, seq)), single)


def tform2eul(tform: np.ndarray, seq: str = "ZYX") -> np.ndarray:
    """Transform (4,4)/(N,4,4) -> Euler angles (3,)/(N,3) of its rotation; ranges as :func:`rotm2eul`."""
    seq = check_seq(seq)
    tform_arr, single = as_stack(tform, "tform", (4, 4))
    check_tforms(tform_arr, "tform", single)
    return unstack(rotations_to_eul(tform_arr[:, :3, :3], seq), single)
