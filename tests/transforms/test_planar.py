"""Planar poses [x y theta] to and from 4x4 and 3x3 transforms, and wrap_to_pi."""

from __future__ import annotations

import numpy as np
import pytest

from bagtools.transforms import eul2tform, pose2tform, pose2tform2d, tform2d2pose, tform2pose, wrap_to_pi
from tests.transforms.conftest import rot_z

PI = np.pi


def test_pose2tform_known_value() -> None:
    tform = pose2tform([1.0, 2.0, PI / 2])
    expected = np.eye(4)
    expected[:3, :3] = rot_z(PI / 2)
    expected[:2, 3] = [1.0, 2.0]
    np.testing.assert_allclose(tform, expected, atol=1e-15)
    # T_a_b maps a point of frame b into frame a: b's x axis points along a's y axis.
    np.testing.assert_allclose(tform @ [1.0, 0, 0, 1], [1.0, 3.0, 0, 1], atol=1e-15)


def test_pose2tform2d_known_value() -> None:
    tform2d = pose2tform2d([1.0, 2.0, PI / 2])
    np.testing.assert_allclose(tform2d, [[0, -1, 1], [1, 0, 2], [0, 0, 1]], atol=1e-15)


@pytest.mark.parametrize("to_tform, from_tform", [(pose2tform, tform2pose), (pose2tform2d, tform2d2pose)])
def test_round_trip(rng: np.random.Generator, to_tform, from_tform) -> None:
    pose = np.column_stack([rng.normal(size=(500, 2)) * 50, rng.uniform(-PI, PI, size=500)])
    np.testing.assert_allclose(from_tform(to_tform(pose)), pose, atol=1e-12)


@pytest.mark.parametrize("from_tform, to_tform", [(tform2pose, pose2tform), (tform2d2pose, pose2tform2d)])
def test_theta_is_wrapped_to_half_open_interval(from_tform, to_tform) -> None:
    pose = np.array([[0, 0, PI], [0, 0, -PI], [0, 0, 3 * PI / 2], [0, 0, -7.0], [0, 0, 0.0]])
    theta = from_tform(to_tform(pose))[:, 2]
    np.testing.assert_allclose(theta, [PI, PI, -PI / 2, -7.0 + 2 * PI, 0.0], atol=1e-12)
    assert np.all((theta > -PI) & (theta <= PI))


def test_tform2pose_keeps_heading_of_tilted_transform() -> None:
    tform = eul2tform([0.7, 0.1, -0.2])  # yaw, pitch, roll
    tform[:3, 3] = [4.0, 5.0, 6.0]
    np.testing.assert_allclose(tform2pose(tform), [4.0, 5.0, 0.7], atol=1e-12)


def test_wrap_to_pi() -> None:
    angles = np.array([PI, -PI, 3 * PI, -3 * PI, 0.5, -0.5, 2 * PI, 7.0])
    np.testing.assert_allclose(wrap_to_pi(angles), [PI, PI, PI, PI, 0.5, -0.5, 0.0, 7.0 - 2 * PI], atol=1e-12)
    assert isinstance(wrap_to_pi(-PI), float)
    assert wrap_to_pi(-PI) == PI
    assert wrap_to_pi(np.zeros((2, 3))).shape == (2, 3)


def test_single_and_stack_shapes(rng: np.random.Generator) -> None:
    pose = rng.normal(size=(4, 3))
    for func, stack, out_item in [
        (pose2tform, pose, (4, 4)),
        (pose2tform2d, pose, (3, 3)),
        (tform2pose, pose2tform(pose), (3,)),
        (tform2d2pose, pose2tform2d(pose), (3,)),
    ]:
        assert func(stack).shape == (4, *out_item), func.__name__
        assert func(stack[2]).shape == out_item, func.__name__
        np.testing.assert_allclose(func(stack[2]), func(stack)[2], atol=1e-15, err_msg=func.__name__)


def test_fast_planar_helpers_equal_the_transforms_module() -> None:
    from bagtools.transforms.planar import se2_between_fast as _between
    from bagtools.transforms.planar import se2_compose_fast as _compose
    from bagtools.transforms import se2_between as between
    from bagtools.transforms import se2_compose as compose

    rng = np.random.default_rng(3)
    for _ in range(50):
        a, b = rng.uniform(-4, 4, 3), rng.uniform(-4, 4, 3)
        np.testing.assert_allclose(_compose(a, b), compose(a, b), atol=1e-12)
        d1, d2 = _between(a, b), between(a, b)
        np.testing.assert_allclose(d1[:2], d2[:2], atol=1e-12)
        assert abs((d1[2] - d2[2] + np.pi) % (2 * np.pi) - np.pi) < 1e-12
