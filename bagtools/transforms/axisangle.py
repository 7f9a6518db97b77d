"""Axis-angle [x y z theta] to and from rotation matrices and transforms (MATLAB names).

axang is (4,) or (N,4): a rotation axis (normalized on input; need not be unit)
and an angle theta in radians, right-handed about the axis.
"""

from __future__ import annotations

import numpy as np

from bagtools.transforms.checks import as_stack, check_nonzero, check_rotations, check_tforms
from bagtools.transforms.quaternions import quats_to_axang, rotation_to_wxyz
from bagtools.transforms.rotations import rotations_to_tforms, unstack


def _axang_rotations(axang: object) -> tuple[np.ndarray, bool]:
    from scipy.spatial.transform import Rotation

    axang_arr, single = as_stack(axang, "axang", (4,))
    axis_norm = check_nonzero(axang_arr[:, :3], "axang", single, "rotation axis")
    rotvec = axang_arr[:, :3] * (axang_arr[:, 3] / axis_norm)[:, None]
    return Rotation.from_rotvec(rotvec).as_matrix(), single


def _rotations_axang(rotm: np.ndarray) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    # Through the canonical (w >= 0) quaternion: theta in [0, pi], and at exactly pi
    # the axis has its first nonzero component positive (Rx(pi) -> [1 0 0 pi], as MATLAB).
    return quats_to_axang(rotation_to_wxyz(Rotation.from_matrix(rotm)))


def axang2rotm(axang: np.ndarray) -> np.ndarray:
    """Axis-angle [x y z theta] (4,)/(N,4), radians, axis normalized first -> rotation matrix (3,3)/(N,3,3)."""
    rotm, single = _axang_rotations(axang)
    return unstack(rotm, single)


def rotm2axang(rotm: np.ndarray) -> np.ndarray:
    """Rotation matrix (3,3)/(N,3,3) -> axis-angle [x y z theta] (4,)/(N,4): unit axis, theta in [0, pi].

    The identity gives [0 0 1 0]; a 180-degree rotation gives the axis whose first
    nonzero component is positive.
    """
    rotm_arr, single = as_stack(rotm, "rotm", (3, 3))
    check_rotations(rotm_arr, "rotm", single)
    return unstack(_rotations_axang(rotm_arr), single)


def axang2tform(axang: np.ndarray) -> np.ndarray:
    """Axis-angle [x y z theta] (4,)/(N,4), radians -> transform (4,4)/(N,4,4), zero translation."""
    rotm, single = _axang_rotations(axang)
    return unstack(rotations_to_tforms(rotm), single)


def tform2axang(tform: np.ndarray) -> np.ndarray:
    """Transform (4,4)/(N,4,4) -> axis-angle [x y z theta] (4,)/(N,4) of its rotation, as :func:`rotm2axang`."""
    tform_arr, single = as_stack(tform, "tform", (4, 4))
    check_tforms(tform_arr, "tform", single)
    return unstack(_rotations_axang(tform_arr[:, :3, :3]), single)
