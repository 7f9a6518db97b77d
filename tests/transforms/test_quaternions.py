"""Quaternions [w x y z]: known values, Hamilton product order, w >= 0, normalization, rotatepoint, round trips."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from bagtools.transforms import (
    axang2quat,
    eul2quat,
    eul2rotm,
    quat2axang,
    quat2eul,
    quat2rotm,
    quat2tform,
    quat2xyzw,
    quatconj,
    quatinv,
    quatmultiply,
    rotatepoint,
    rotm2eul,
    rotm2quat,
    tform2quat,
    xyzw2quat,
)
from tests.transforms.conftest import random_quats, rot_x, rot_y, rot_z

PI = np.pi
H = np.sqrt(0.5)
RY_90 = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])


def same_rotation(quat_a: np.ndarray, quat_b: np.ndarray, atol: float = 1e-12) -> None:
    """q and -q are the same rotation: compare up to sign, row by row."""
    dots = np.abs(np.sum(np.atleast_2d(quat_a) * np.atleast_2d(quat_b), axis=-1))
    np.testing.assert_allclose(dots, 1.0, atol=atol)


# ---- known values (MATLAB documentation examples, worked out by hand) ----

def test_eul2quat_and_quat2rotm_known_values() -> None:
    np.testing.assert_allclose(eul2quat([0, PI / 2, 0]), [H, 0, H, 0], atol=1e-15)
    np.testing.assert_allclose(quat2rotm([H, 0, H, 0]), RY_90, atol=1e-15)
    np.testing.assert_allclose(rotm2quat(RY_90), [H, 0, H, 0], atol=1e-15)


def test_quat2eul_known_values() -> None:
    np.testing.assert_allclose(quat2eul([H, H, 0, 0]), [0, 0, PI / 2], atol=1e-15)
    np.testing.assert_allclose(quat2eul([H, H, 0, 0], "ZYZ"), [PI / 2, -PI / 2, -PI / 2], atol=1e-15)


def test_quat_axang_known_values() -> None:
    np.testing.assert_allclose(axang2quat([1, 0, 0, PI / 2]), [H, H, 0, 0], atol=1e-15)
    np.testing.assert_allclose(quat2axang([H, H, 0, 0]), [1, 0, 0, PI / 2], atol=1e-15)
    np.testing.assert_array_equal(quat2axang([1, 0, 0, 0]), [0, 0, 1, 0])
    np.testing.assert_array_equal(quat2axang([-2, 0, 0, 0]), [0, 0, 1, 0])


def test_quat2axang_negative_w_gives_negative_angle() -> None:
    # w < 0: 2 acos(w) > pi, wrapped to a negative angle about the same axis, as MATLAB.
    quat = axang2quat([0, 0, 1, 1.5 * PI])  # w = cos(3pi/4) < 0
    assert quat[0] < 0
    np.testing.assert_allclose(quat2axang(quat), [0, 0, 1, -0.5 * PI], atol=1e-12)


def test_quatmultiply_matlab_example() -> None:
    np.testing.assert_allclose(quatmultiply([1, 0, 1, 0], [1, 0.5, 0.5, 0.75]), [0.5, 1.25, 1.5, 0.25], atol=1e-15)


def test_quatconj_and_quatinv_known_values() -> None:
    np.testing.assert_array_equal(quatconj([H, H, 0, 0]), [H, -H, 0, 0])
    np.testing.assert_allclose(quatinv([1, 1, 1, 1]), [0.25, -0.25, -0.25, -0.25], atol=1e-15)
    np.testing.assert_allclose(quatinv([2, 0, 0, 0]), [0.5, 0, 0, 0], atol=1e-15)


def test_quatconj_accepts_zero_quaternion() -> None:
    np.testing.assert_array_equal(quatconj([0, 0, 0, 0]), [0, 0, 0, 0])


def test_ros_order_helpers() -> None:
    np.testing.assert_array_equal(xyzw2quat([1, 2, 3, 4]), [4, 1, 2, 3])
    np.testing.assert_array_equal(quat2xyzw([4, 1, 2, 3]), [1, 2, 3, 4])
    stack = np.arange(12.0).reshape(3, 4)
    np.testing.assert_array_equal(xyzw2quat(quat2xyzw(stack)), stack)


# ---- Hamilton product order, inverse ----

def test_quatmultiply_order_matches_matrix_product(rng: np.random.Generator) -> None:
    quat_a, quat_b = random_quats(rng, 300), random_quats(rng, 300)
    product = quatmultiply(quat_a, quat_b)
    np.testing.assert_allclose(quat2rotm(product), quat2rotm(quat_a) @ quat2rotm(quat_b), atol=1e-12)
    assert not np.allclose(quat2rotm(product), quat2rotm(quat_b) @ quat2rotm(quat_a), atol=1e-3)


def test_quatmultiply_broadcasts_one_item(rng: np.random.Generator) -> None:
    quat_a, quat_b = random_quats(rng, 1)[0], random_quats(rng, 7)
    expected = np.stack([quatmultiply(quat_a, q) for q in quat_b])
    np.testing.assert_allclose(quatmultiply(quat_a, quat_b), expected, atol=1e-15)
    expected = np.stack([quatmultiply(q, quat_a) for q in quat_b])
    np.testing.assert_allclose(quatmultiply(quat_b, quat_a), expected, atol=1e-15)
    assert quatmultiply(quat_a, quat_a).shape == (4,)
    assert quatmultiply(quat_a[None], quat_a).shape == (1, 4)


def test_quatinv_is_multiplicative_inverse(rng: np.random.Generator) -> None:
    quat = rng.normal(size=(100, 4)) * rng.uniform(0.1, 10, size=(100, 1))  # not unit
    identity = np.tile([1.0, 0, 0, 0], (100, 1))
    np.testing.assert_allclose(quatmultiply(quat, quatinv(quat)), identity, atol=1e-12)
    np.testing.assert_allclose(quatmultiply(quatinv(quat), quat), identity, atol=1e-12)


# ---- w >= 0, normalization ----

def test_rotm2quat_has_nonnegative_w(rng: np.random.Generator) -> None:
    rotm = Rotation.random(2000, random_state=rng).as_matrix()
    quat = rotm2quat(rotm)
    assert np.all(quat[:, 0] >= 0)
    np.testing.assert_allclose(np.linalg.norm(quat, axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(quat2rotm(quat), rotm, atol=1e-12)
    assert np.all(tform2quat(quat2tform(quat))[:, 0] >= 0)


def test_rotm2quat_half_turn_sign() -> None:
    np.testing.assert_allclose(rotm2quat(rot_x(PI)), [0, 1, 0, 0], atol=1e-15)
    np.testing.assert_allclose(rotm2quat(np.diag([-1.0, -1.0, 1.0])), [0, 0, 0, 1], atol=1e-15)


def test_conversions_normalize_the_quaternion(rng: np.random.Generator) -> None:
    quat = random_quats(rng, 50)
    scaled = quat * rng.uniform(0.01, 100, size=(50, 1))
    np.testing.assert_allclose(quat2rotm(scaled), quat2rotm(quat), atol=1e-12)
    np.testing.assert_allclose(quat2eul(scaled), quat2eul(quat), atol=1e-12)
    np.testing.assert_allclose(quat2axang(scaled), quat2axang(quat), atol=1e-12)
    np.testing.assert_allclose(quat2tform(scaled), quat2tform(quat), atol=1e-12)
    points = rng.normal(size=(50, 3))
    np.testing.assert_allclose(rotatepoint(scaled, points), rotatepoint(quat, points), atol=1e-12)


# ---- round trips ----

@pytest.mark.parametrize("seq", ["ZYX", "ZYZ", "XYZ"])
def test_eul_quat_round_trip(rng: np.random.Generator, seq: str) -> None:
    quat = random_quats(rng, 1000)
    same_rotation(eul2quat(quat2eul(quat, seq), seq), quat)
    eul = rng.uniform(-3, 3, size=(200, 3))
    np.testing.assert_allclose(quat2rotm(eul2quat(eul, seq)), eul2rotm(eul, seq), atol=1e-12)


def test_quat2eul_matches_rotm2eul_at_gimbal_lock() -> None:
    quat = eul2quat([0.3, PI / 2, 0.5])
    np.testing.assert_allclose(quat2eul(quat), rotm2eul(quat2rotm(quat)), atol=1e-15)


def test_eul2quat_is_product_of_elementary_quaternions() -> None:
    yaw, pitch, roll = 3.0, 3.0, 3.0  # large angles: w of the product is negative, kept as MATLAB does
    qz = [np.cos(yaw / 2), 0, 0, np.sin(yaw / 2)]
    qy = [np.cos(pitch / 2), 0, np.sin(pitch / 2), 0]
    qx = [np.cos(roll / 2), np.sin(roll / 2), 0, 0]
    np.testing.assert_allclose(eul2quat([yaw, pitch, roll]), quatmultiply(quatmultiply(qz, qy), qx), atol=1e-15)


def test_axang_quat_round_trip(rng: np.random.Generator) -> None:
    quat = random_quats(rng, 1000)
    axang = quat2axang(quat)
    assert np.all(np.abs(axang[:, 3]) <= PI)
    np.testing.assert_allclose(np.linalg.norm(axang[:, :3], axis=1), 1.0, atol=1e-12)
    same_rotation(axang2quat(axang), quat)


def test_axang2quat_normalizes_axis() -> None:
    np.testing.assert_allclose(axang2quat([0, 0, 5, PI / 2]), axang2quat([0, 0, 1, PI / 2]), atol=1e-15)


# ---- rotatepoint: p' = q p q^-1 ----

def test_rotatepoint_known_value() -> None:
    quat_z90 = [H, 0, 0, H]
    np.testing.assert_allclose(rotatepoint(quat_z90, [1, 0, 0]), [0, 1, 0], atol=1e-15)


def test_rotatepoint_matches_rotation_matrix_and_sandwich(rng: np.random.Generator) -> None:
    quat = random_quats(rng, 200)
    points = rng.normal(size=(200, 3))
    expected = np.einsum("nij,nj->ni", quat2rotm(quat), points)
    np.testing.assert_allclose(rotatepoint(quat, points), expected, atol=1e-12)
    pure = np.concatenate([np.zeros((200, 1)), points], axis=1)
    sandwich = quatmultiply(quatmultiply(quat, pure), quatinv(quat))
    np.testing.assert_allclose(rotatepoint(quat, points), sandwich[:, 1:], atol=1e-12)


def test_rotatepoint_broadcasting_shapes(rng: np.random.Generator) -> None:
    quat = random_quats(rng, 6)
    points = rng.normal(size=(6, 3))
    one_q = rotatepoint(quat[0], points)
    assert one_q.shape == (6, 3)
    np.testing.assert_allclose(one_q, points @ quat2rotm(quat[0]).T, atol=1e-12)
    one_p = rotatepoint(quat, points[0])
    assert one_p.shape == (6, 3)
    np.testing.assert_allclose(one_p, quat2rotm(quat) @ points[0], atol=1e-12)
    assert rotatepoint(quat[0], points[0]).shape == (3,)
    assert rotatepoint(quat[:1], points[:1]).shape == (1, 3)


# ---- shapes ----

def test_single_and_stack_shapes(rng: np.random.Generator) -> None:
    quat = random_quats(rng, 5)
    rotm = quat2rotm(quat)
    tform = quat2tform(quat)
    cases = [
        (quat2rotm, quat, (3, 3)),
        (quat2tform, quat, (4, 4)),
        (quat2eul, quat, (3,)),
        (quat2axang, quat, (4,)),
        (quatconj, quat, (4,)),
        (quatinv, quat, (4,)),
        (quat2xyzw, quat, (4,)),
        (xyzw2quat, quat, (4,)),
        (rotm2quat, rotm, (4,)),
        (tform2quat, tform, (4,)),
        (eul2quat, quat2eul(quat), (4,)),
        (axang2quat, quat2axang(quat), (4,)),
    ]
    for func, stack, out_item in cases:
        out_stack = func(stack)
        assert out_stack.shape == (5, *out_item), func.__name__
        out_one = func(stack[3])
        assert out_one.shape == out_item, func.__name__
        np.testing.assert_allclose(out_one, out_stack[3], atol=1e-15, err_msg=func.__name__)


def test_quat2rotm_against_hand_built_axes() -> None:
    for angle in (0.3, -1.2, 2.9):
        c, s = np.cos(angle / 2), np.sin(angle / 2)
        np.testing.assert_allclose(quat2rotm([c, s, 0, 0]), rot_x(angle), atol=1e-15)
        np.testing.assert_allclose(quat2rotm([c, 0, s, 0]), rot_y(angle), atol=1e-15)
        np.testing.assert_allclose(quat2rotm([c, 0, 0, s]), rot_z(angle), atol=1e-15)
