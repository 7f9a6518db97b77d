"""Axis-angle [x y z theta]: known values, identity and half turns, ranges, round trips, shapes."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from bagtools.transforms import axang2rotm, axang2tform, rotm2axang, tform2axang
from tests.transforms.conftest import rot_x, rot_z

PI = np.pi
H = np.sqrt(0.5)
RY_90 = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])


def test_axang2rotm_matlab_example() -> None:
    np.testing.assert_allclose(axang2rotm([0, 1, 0, PI / 2]), RY_90, atol=1e-15)
    expected = np.eye(4)
    expected[:3, :3] = RY_90
    np.testing.assert_allclose(axang2tform([0, 1, 0, PI / 2]), expected, atol=1e-15)


def test_rotm2axang_matlab_example_half_turn() -> None:
    np.testing.assert_allclose(rotm2axang(np.diag([1.0, -1.0, -1.0])), [1, 0, 0, PI], atol=1e-15)
    np.testing.assert_allclose(rotm2axang(np.diag([-1.0, 1.0, -1.0])), [0, 1, 0, PI], atol=1e-15)
    # exact half turns: the axis sign is fixed (first nonzero component positive)
    np.testing.assert_allclose(tform2axang(np.diag([-1.0, -1.0, 1.0, 1.0])), [0, 0, 1, PI], atol=1e-15)
    half_turn_xy = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])  # about [1 1 0]
    np.testing.assert_allclose(rotm2axang(half_turn_xy), [H, H, 0, PI], atol=1e-15)


def test_rotm2axang_identity() -> None:
    np.testing.assert_array_equal(rotm2axang(np.eye(3)), [0, 0, 1, 0])
    np.testing.assert_array_equal(tform2axang(np.eye(4)), [0, 0, 1, 0])


def test_axang2rotm_normalizes_axis_and_matches_hand_built() -> None:
    np.testing.assert_allclose(axang2rotm([3, 0, 0, 0.7]), rot_x(0.7), atol=1e-15)
    np.testing.assert_allclose(axang2rotm([0, 0, 0.2, -2.0]), rot_z(-2.0), atol=1e-15)


def test_negative_angle_comes_back_positive_about_flipped_axis() -> None:
    np.testing.assert_allclose(rotm2axang(axang2rotm([0, 0, 1, -0.4])), [0, 0, -1, 0.4], atol=1e-15)


def test_round_trip_and_range(rng: np.random.Generator) -> None:
    rotm = Rotation.random(2000, random_state=rng).as_matrix()
    axang = rotm2axang(rotm)
    assert np.all((axang[:, 3] >= 0) & (axang[:, 3] <= PI))
    np.testing.assert_allclose(np.linalg.norm(axang[:, :3], axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(axang2rotm(axang), rotm, atol=1e-12)
    tform = axang2tform(axang)
    np.testing.assert_allclose(tform[:, :3, :3], rotm, atol=1e-12)
    np.testing.assert_allclose(tform2axang(tform), axang, atol=1e-12)


def test_single_and_stack_shapes(rng: np.random.Generator) -> None:
    axang = np.concatenate([rng.normal(size=(4, 3)), rng.uniform(-3, 3, size=(4, 1))], axis=1)
    rotm, tform = axang2rotm(axang), axang2tform(axang)
    for func, stack, out_item in [
        (axang2rotm, axang, (3, 3)),
        (axang2tform, axang, (4, 4)),
        (rotm2axang, rotm, (4,)),
        (tform2axang, tform, (4,)),
    ]:
        assert func(stack).shape == (4, *out_item), func.__name__
        np.testing.assert_allclose(func(stack[1]), func(stack)[1], atol=1e-15, err_msg=func.__name__)
        assert func(stack[1]).shape == out_item, func.__name__
