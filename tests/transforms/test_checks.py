"""Every bad input is a one-line ValueError naming the argument and the problem."""

from __future__ import annotations

import re

import numpy as np
import pytest

import bagtools.transforms as tr

RY_90 = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])
REFLECTION = np.diag([1.0, 1.0, -1.0])
SCALED = 2.0 * np.eye(3)
SHEARED = np.array([[1.0, 0.1, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])


def _tform(rotm: np.ndarray) -> np.ndarray:
    tform = np.eye(4)
    tform[:3, :3] = rotm
    return tform


def raises(match: str):
    return pytest.raises(ValueError, match=re.escape(match))


# ---- shapes ----

@pytest.mark.parametrize(
    ("func", "bad", "message"),
    [
        (tr.rotm2eul, np.eye(4)[:3], "rotm must have shape (3,3) or (N,3,3), got (3,4)"),
        (tr.rotm2quat, np.zeros((2, 3)), "rotm must have shape (3,3) or (N,3,3), got (2,3)"),
        (tr.rotm2axang, np.zeros((2, 2, 3, 3)), "rotm must have shape (3,3) or (N,3,3), got (2,2,3,3)"),
        (tr.rotm2tform, np.zeros(9), "rotm must have shape (3,3) or (N,3,3), got (9,)"),
        (tr.tform2rotm, np.eye(3), "tform must have shape (4,4) or (N,4,4), got (3,3)"),
        (tr.tform2trvec, np.eye(3), "tform must have shape (4,4) or (N,4,4), got (3,3)"),
        (tr.tform2eul, np.eye(3), "tform must have shape (4,4) or (N,4,4), got (3,3)"),
        (tr.tform2quat, np.eye(3), "tform must have shape (4,4) or (N,4,4), got (3,3)"),
        (tr.tform2axang, np.eye(3), "tform must have shape (4,4) or (N,4,4), got (3,3)"),
        (tr.tform2pose, np.eye(3), "tform must have shape (4,4) or (N,4,4), got (3,3)"),
        (tr.tform2d2pose, np.eye(4), "tform2d must have shape (3,3) or (N,3,3), got (4,4)"),
        (tr.trvec2tform, [1, 2], "trvec must have shape (3,) or (N,3), got (2,)"),
        (tr.eul2rotm, [1, 2, 3, 4], "eul must have shape (3,) or (N,3), got (4,)"),
        (tr.eul2tform, np.zeros((5, 2)), "eul must have shape (3,) or (N,3), got (5,2)"),
        (tr.eul2quat, 1.0, "eul must have shape (3,) or (N,3), got ()"),
        (tr.quat2rotm, [1, 0, 0], "quat must have shape (4,) or (N,4), got (3,)"),
        (tr.quat2eul, np.zeros((3, 3)), "quat must have shape (4,) or (N,4), got (3,3)"),
        (tr.quat2axang, [1, 0, 0], "quat must have shape (4,) or (N,4), got (3,)"),
        (tr.quat2tform, [1, 0, 0], "quat must have shape (4,) or (N,4), got (3,)"),
        (tr.quatconj, [1, 0, 0], "quat must have shape (4,) or (N,4), got (3,)"),
        (tr.quatinv, [1, 0, 0], "quat must have shape (4,) or (N,4), got (3,)"),
        (tr.quat2xyzw, [1, 0, 0], "quat must have shape (4,) or (N,4), got (3,)"),
        (tr.xyzw2quat, [1, 0, 0], "quat_xyzw must have shape (4,) or (N,4), got (3,)"),
        (tr.axang2rotm, [0, 0, 1], "axang must have shape (4,) or (N,4), got (3,)"),
        (tr.axang2tform, [0, 0, 1], "axang must have shape (4,) or (N,4), got (3,)"),
        (tr.axang2quat, [0, 0, 1], "axang must have shape (4,) or (N,4), got (3,)"),
        (tr.pose2tform, [1, 2], "pose_xytheta must have shape (3,) or (N,3), got (2,)"),
        (tr.pose2tform2d, [1, 2, 3, 4], "pose_xytheta must have shape (3,) or (N,3), got (4,)"),
    ],
)
def test_wrong_shape(func, bad, message: str) -> None:
    with raises(message):
        func(bad)


def test_wrong_shape_in_binary_functions() -> None:
    with raises("quat_a must have shape (4,) or (N,4), got (3,)"):
        tr.quatmultiply([1, 0, 0], [1, 0, 0, 0])
    with raises("quat_b must have shape (4,) or (N,4), got (2,3)"):
        tr.quatmultiply([1, 0, 0, 0], np.zeros((2, 3)))
    with raises("points must have shape (3,) or (N,3), got (2,)"):
        tr.rotatepoint([1, 0, 0, 0], [1, 2])
    with raises("quat must have shape (4,) or (N,4), got (3,)"):
        tr.rotatepoint([1, 0, 0], [1, 2, 3])


def test_mismatched_stack_counts() -> None:
    with raises("quat_a has 2 items but quat_b has 3"):
        tr.quatmultiply(np.tile([1.0, 0, 0, 0], (2, 1)), np.tile([1.0, 0, 0, 0], (3, 1)))
    with raises("quat has 2 items but points has 4"):
        tr.rotatepoint(np.tile([1.0, 0, 0, 0], (2, 1)), np.zeros((4, 3)))


# ---- not numbers, not finite ----

def test_non_numeric_input() -> None:
    with raises("eul must hold real numbers, got dtype <U1"):
        tr.eul2rotm(["a", "b", "c"])
    with raises("quat must hold real numbers, got dtype complex128"):
        tr.quat2rotm(np.array([1j, 0, 0, 0]))
    with raises("rotm must hold real numbers, got dtype bool"):
        tr.rotm2quat(np.eye(3, dtype=bool))
    with raises("trvec must be a numeric array"):
        tr.trvec2tform([[1, 2, 3], [1, 2]])


def test_nan_and_inf() -> None:
    with raises("eul has a NaN or infinite value"):
        tr.eul2rotm([0.0, np.nan, 0.0])
    stack = np.zeros((4, 3))
    stack[2, 1] = np.inf
    with raises("pose_xytheta has a NaN or infinite value at index 2"):
        tr.pose2tform(stack)
    rotm = np.tile(np.eye(3), (3, 1, 1))
    rotm[1, 0, 0] = np.nan
    with raises("rotm has a NaN or infinite value at index 1"):
        tr.rotm2eul(rotm)


# ---- not a rotation ----

@pytest.mark.parametrize("func", [tr.rotm2eul, tr.rotm2quat, tr.rotm2axang, tr.rotm2tform])
@pytest.mark.parametrize(
    ("bad", "problem"),
    [(SCALED, "not orthonormal"), (SHEARED, "not orthonormal"), (REFLECTION, "determinant is -1 (a reflection)")],
)
def test_rotm_not_a_rotation(func, bad: np.ndarray, problem: str) -> None:
    with raises(f"rotm is not a rotation matrix: {problem}"):
        func(bad)


@pytest.mark.parametrize("func", [tr.tform2rotm, tr.tform2eul, tr.tform2quat, tr.tform2axang, tr.tform2trvec, tr.tform2pose])
def test_tform_not_rigid(func) -> None:
    with raises("tform rotation part is not a rotation matrix: determinant is -1"):
        func(_tform(REFLECTION))
    with raises("tform rotation part is not a rotation matrix: not orthonormal"):
        func(_tform(SCALED))
    bad_bottom = np.eye(4)
    bad_bottom[3, 0] = 0.5
    with raises("tform is not a homogeneous transform: bottom row is not [0 0 0 1]"):
        func(bad_bottom)


def test_tform2d_not_rigid() -> None:
    with raises("tform2d rotation part is not a rotation matrix: determinant is -1"):
        tr.tform2d2pose(np.diag([1.0, -1.0, 1.0]))
    with raises("tform2d rotation part is not a rotation matrix: not orthonormal"):
        tr.tform2d2pose(np.diag([2.0, 2.0, 1.0]))
    with raises("tform2d is not a homogeneous transform: bottom row is not [0 0 1]"):
        tr.tform2d2pose(np.array([[1.0, 0, 0], [0, 1, 0], [0, 1, 1]]))


def test_bad_item_index_is_named_in_stack() -> None:
    rotm = np.tile(np.eye(3), (5, 1, 1))
    rotm[3] = REFLECTION
    with raises("rotm is not a rotation matrix at index 3: determinant is -1"):
        tr.rotm2quat(rotm)


def test_rotation_tolerance() -> None:
    almost = RY_90 + 1e-9  # within 1e-6: accepted
    tr.rotm2eul(almost)
    off = RY_90.copy()
    off[0, 2] += 1e-5  # beyond 1e-6: rejected
    with raises("rotm is not a rotation matrix: not orthonormal"):
        tr.rotm2eul(off)


# ---- zero quaternions and axes ----

@pytest.mark.parametrize("func", [tr.quat2rotm, tr.quat2eul, tr.quat2axang, tr.quat2tform, tr.quatinv])
def test_zero_quaternion(func) -> None:
    with raises("quat has a zero quaternion (norm 0): it does not describe a rotation"):
        func([0.0, 0.0, 0.0, 0.0])
    stack = np.tile([1.0, 0, 0, 0], (3, 1))
    stack[1] = 0.0
    with raises("quat has a zero quaternion at index 1"):
        func(stack)


def test_zero_quaternion_in_rotatepoint() -> None:
    with raises("quat has a zero quaternion"):
        tr.rotatepoint([0, 0, 0, 0], [1, 2, 3])


@pytest.mark.parametrize("func", [tr.axang2rotm, tr.axang2tform, tr.axang2quat])
def test_zero_axis(func) -> None:
    with raises("axang has a zero rotation axis (norm 0)"):
        func([0, 0, 0, 1.0])


# ---- Euler sequences ----

@pytest.mark.parametrize("func", [tr.eul2rotm, tr.eul2tform, tr.eul2quat])
@pytest.mark.parametrize("seq", ["ZXZ", "XYZW", "", "abc", 3, None])
def test_unknown_sequence_from_angles(func, seq) -> None:
    with raises(f"unknown Euler sequence {seq!r}: use one of 'ZYX', 'ZYZ', 'XYZ'"):
        func([0.1, 0.2, 0.3], seq)


@pytest.mark.parametrize(
    ("func", "arg"), [(tr.rotm2eul, np.eye(3)), (tr.tform2eul, np.eye(4)), (tr.quat2eul, [1.0, 0, 0, 0])]
)
def test_unknown_sequence_to_angles(func, arg) -> None:
    with raises("unknown Euler sequence 'YXY'"):
        func(arg, "YXY")


def test_messages_are_one_line() -> None:
    for call in (
        lambda: tr.rotm2eul(np.eye(4)),
        lambda: tr.rotm2quat(REFLECTION),
        lambda: tr.quat2rotm([0, 0, 0, 0]),
        lambda: tr.eul2rotm([0, 0, 0], "Q"),
    ):
        with pytest.raises(ValueError) as info:
            call()
        assert "\n" not in str(info.value)
