"""Rotation matrices, transforms, translations and Euler angles: known values, round trips, ranges, gimbal lock."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from bagtools.transforms import (
    eul2rotm,
    eul2tform,
    rotm2eul,
    rotm2tform,
    tform2eul,
    tform2rotm,
    tform2trvec,
    trvec2tform,
)
from tests.transforms.conftest import intrinsic, rot_x, rot_y, rot_z

PI = np.pi
RY_90 = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])


def random_eul(rng: np.random.Generator, n: int, seq: str) -> np.ndarray:
    """Euler triples strictly inside rotm2eul's output ranges for ``seq`` (so the round trip is exact)."""
    eul = rng.uniform(-PI + 1e-6, PI - 1e-6, size=(n, 3))
    if seq == "ZYZ":
        eul[:, 1] = rng.uniform(-PI + 1e-3, -1e-3, size=n)
    else:
        eul[:, 1] = rng.uniform(-PI / 2 + 1e-3, PI / 2 - 1e-3, size=n)
    return eul


# ---- known values (MATLAB documentation examples, worked out by hand) ----

def test_eul2rotm_matlab_example_zyx() -> None:
    np.testing.assert_allclose(eul2rotm([0, PI / 2, 0]), RY_90, atol=1e-15)


def test_eul2rotm_matlab_example_zyz() -> None:
    # Rz(0) Ry(pi/2) Rz(pi/2)
    expected = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    np.testing.assert_allclose(eul2rotm([0, PI / 2, PI / 2], "ZYZ"), expected, atol=1e-15)


def test_rotm2eul_matlab_examples() -> None:
    np.testing.assert_allclose(rotm2eul(RY_90), [0.0, PI / 2, 0.0], atol=1e-15)
    # MATLAB's documented ZYZ answer: the middle angle is negative, first/third are -pi.
    np.testing.assert_allclose(rotm2eul(RY_90, "ZYZ"), [-PI, -PI / 2, -PI], atol=1e-15)


def test_eul2tform_matlab_example() -> None:
    expected = np.eye(4)
    expected[:3, :3] = RY_90
    np.testing.assert_allclose(eul2tform([0, PI / 2, 0]), expected, atol=1e-15)


def test_trvec_tform_known_values() -> None:
    tform = trvec2tform([0.5, 6, 100])
    expected = np.eye(4)
    expected[:3, 3] = [0.5, 6, 100]
    np.testing.assert_array_equal(tform, expected)
    np.testing.assert_array_equal(tform2trvec(tform), [0.5, 6, 100])


def test_rotm_tform_known_values() -> None:
    tform = rotm2tform(RY_90)
    np.testing.assert_array_equal(tform[:3, :3], RY_90)
    np.testing.assert_array_equal(tform[3], [0, 0, 0, 1])
    np.testing.assert_array_equal(tform[:3, 3], [0, 0, 0])
    moved = tform.copy()
    moved[:3, 3] = [1, 2, 3]
    np.testing.assert_array_equal(tform2rotm(moved), RY_90)


# ---- conventions against hand-built elementary rotations ----

@pytest.mark.parametrize("seq", ["ZYX", "ZYZ", "XYZ"])
def test_eul2rotm_is_intrinsic_product(rng: np.random.Generator, seq: str) -> None:
    eul = rng.uniform(-4, 4, size=(20, 3))
    expected = np.stack([intrinsic(e, seq) for e in eul])
    np.testing.assert_allclose(eul2rotm(eul, seq), expected, atol=1e-14)
    np.testing.assert_allclose(eul2tform(eul, seq)[:, :3, :3], expected, atol=1e-14)


def test_zyx_is_yaw_pitch_roll() -> None:
    yaw, pitch, roll = 0.3, -0.2, 0.1
    np.testing.assert_allclose(eul2rotm([yaw, pitch, roll]), rot_z(yaw) @ rot_y(pitch) @ rot_x(roll), atol=1e-15)


def test_sequence_is_case_insensitive() -> None:
    eul = [0.1, 0.2, 0.3]
    np.testing.assert_array_equal(eul2rotm(eul, "zyz"), eul2rotm(eul, "ZYZ"))


# ---- round trips and ranges on random stacks ----

@pytest.mark.parametrize("seq", ["ZYX", "ZYZ", "XYZ"])
def test_eul_round_trip(rng: np.random.Generator, seq: str) -> None:
    eul = random_eul(rng, 2000, seq)
    np.testing.assert_allclose(rotm2eul(eul2rotm(eul, seq), seq), eul, atol=1e-9)
    np.testing.assert_allclose(tform2eul(eul2tform(eul, seq), seq), eul, atol=1e-9)


@pytest.mark.parametrize("seq", ["ZYX", "ZYZ", "XYZ"])
def test_rotm2eul_ranges_and_reconstruction(rng: np.random.Generator, seq: str) -> None:
    rotm = Rotation.random(2000, random_state=rng).as_matrix()
    eul = rotm2eul(rotm, seq)
    assert np.all(np.abs(eul[:, [0, 2]]) <= PI)
    if seq == "ZYZ":
        assert np.all((eul[:, 1] >= -PI) & (eul[:, 1] <= 0.0))
    else:
        assert np.all(np.abs(eul[:, 1]) <= PI / 2)
    np.testing.assert_allclose(eul2rotm(eul, seq), rotm, atol=1e-12)


@pytest.mark.parametrize("seq", ["ZYX", "XYZ"])
def test_rotm2eul_agrees_with_scipy_away_from_gimbal_lock(rng: np.random.Generator, seq: str) -> None:
    rotm = Rotation.random(500, random_state=rng).as_matrix()
    np.testing.assert_allclose(rotm2eul(rotm, seq), Rotation.from_matrix(rotm).as_euler(seq), atol=1e-9)


def test_rotm2eul_zyz_is_scipys_other_solution(rng: np.random.Generator) -> None:
    rotm = Rotation.random(500, random_state=rng).as_matrix()
    first, middle, third = Rotation.from_matrix(rotm).as_euler("ZYZ").T  # scipy: middle in [0, pi]
    eul = rotm2eul(rotm, "ZYZ")
    np.testing.assert_allclose(eul[:, 1], -middle, atol=1e-9)
    np.testing.assert_allclose(np.cos(eul[:, 0]), -np.cos(first), atol=1e-9)
    np.testing.assert_allclose(np.sin(eul[:, 2]), -np.sin(third), atol=1e-9)


# ---- gimbal lock, as MATLAB: first angle 0, third angle carries the rotation, no warning ----

@pytest.mark.parametrize(
    ("seq", "eul", "expected"),
    [
        ("ZYX", [0.3, PI / 2, 0.5], [0.0, PI / 2, 0.2]),  # Rz(a) Ry(pi/2) Rx(c) = Ry(pi/2) Rx(c - a)
        ("ZYX", [0.3, -PI / 2, 0.5], [0.0, -PI / 2, 0.8]),  # ... Ry(-pi/2) Rx(c + a)
        ("XYZ", [0.3, PI / 2, 0.5], [0.0, PI / 2, 0.8]),  # Rx(a) Ry(pi/2) Rz(c) = Ry(pi/2) Rz(c + a)
        ("XYZ", [0.3, -PI / 2, 0.5], [0.0, -PI / 2, 0.2]),
        ("ZYZ", [0.3, 0.0, 0.5], [0.0, 0.0, 0.8]),  # Rz(a + c)
        ("ZYZ", [0.3, PI, 0.5], [0.0, -PI, 0.2]),  # Rz(a) Ry(pi) Rz(c) = Ry(-pi) Rz(c - a)
    ],
)
def test_gimbal_lock_puts_rotation_in_third_angle(seq: str, eul: list[float], expected: list[float]) -> None:
    rotm = eul2rotm(eul, seq)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        got = rotm2eul(rotm, seq)
    np.testing.assert_allclose(got, expected, atol=1e-12)
    np.testing.assert_allclose(eul2rotm(got, seq), rotm, atol=1e-12)


def test_gimbal_lock_within_a_stack_only_affects_locked_items() -> None:
    eul = np.array([[0.3, 0.2, 0.5], [0.3, PI / 2, 0.5], [-0.1, 0.4, 0.2]])
    got = rotm2eul(eul2rotm(eul))
    np.testing.assert_allclose(got[[0, 2]], eul[[0, 2]], atol=1e-12)
    np.testing.assert_allclose(got[1], [0.0, PI / 2, 0.2], atol=1e-12)


# ---- shapes: one item in, one item out; a stack in, a stack out ----

def test_single_and_stack_shapes(rng: np.random.Generator) -> None:
    eul = rng.uniform(-1, 1, size=(5, 3))
    rotm = eul2rotm(eul)
    tform = eul2tform(eul)
    tform[:, :3, 3] = rng.normal(size=(5, 3))
    cases = [
        (eul2rotm, eul, (3, 3)),
        (eul2tform, eul, (4, 4)),
        (rotm2eul, rotm, (3,)),
        (rotm2tform, rotm, (4, 4)),
        (tform2rotm, tform, (3, 3)),
        (tform2eul, tform, (3,)),
        (tform2trvec, tform, (3,)),
        (trvec2tform, tform[:, :3, 3], (4, 4)),
    ]
    for func, stack, out_item in cases:
        out_stack = func(stack)
        assert out_stack.shape == (5, *out_item), func.__name__
        out_one = func(stack[2])
        assert out_one.shape == out_item, func.__name__
        np.testing.assert_allclose(out_one, out_stack[2], atol=1e-15, err_msg=func.__name__)
        assert func(stack[:1]).shape == (1, *out_item), func.__name__


def test_accepts_lists_and_ints() -> None:
    np.testing.assert_array_equal(eul2rotm([0, 0, 0]), np.eye(3))
    np.testing.assert_array_equal(rotm2tform(np.eye(3, dtype=int)), np.eye(4))


def test_outputs_do_not_alias_inputs() -> None:
    tform = np.eye(4)
    tform2rotm(tform)[0, 0] = 5.0
    tform2trvec(tform)[0] = 5.0
    np.testing.assert_array_equal(tform, np.eye(4))
