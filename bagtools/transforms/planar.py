"""Planar poses [x y theta] to and from 3D (4x4) and 2D (3x3) homogeneous transforms.

pose (3,) or (N,3): x, y in metres, theta in radians about +z (counter-clockwise
seen from above). A pose of frame b in frame a is the transform T_a_b.
"""

from __future__ import annotations

import math

import numpy as np

from bagtools.transforms.checks import as_stack, check_tforms
from bagtools.transforms.rotations import unstack


def wrap_to_pi(angle_rad: np.ndarray | float) -> np.ndarray | float:
    """Wrap angles in radians (any shape) to (-pi, pi]; odd multiples of pi map to +pi."""
    angle = np.asarray(angle_rad, dtype=np.float64)
    wrapped = np.mod(angle + np.pi, 2.0 * np.pi) - np.pi  # [-pi, pi)
    wrapped = np.where(wrapped <= -np.pi, np.pi, wrapped)
    return float(wrapped) if wrapped.ndim == 0 else wrapped


def _planar_tforms(pose: object, size: int) -> tuple[np.ndarray, bool]:
    pose_arr, single = as_stack(pose, "pose_xytheta", (3,))
    cos_t, sin_t = np.cos(pose_arr[:, 2]), np.sin(pose_arr[:, 2])
    tform = np.zeros((len(pose_arr), size, size))
    tform[:, 0, 0], tform[:, 0, 1] = cos_t, -sin_t
    tform[:, 1, 0], tform[:, 1, 1] = sin_t, cos_t
    tform[:, 0, -1], tform[:, 1, -1] = pose_arr[:, 0], pose_arr[:, 1]
    tform[:, range(2, size), range(2, size)] = 1.0
    return tform, single


def _poses(tform: np.ndarray) -> np.ndarray:
    pose = np.empty((len(tform), 3))
    pose[:, 0], pose[:, 1] = tform[:, 0, -1], tform[:, 1, -1]
    pose[:, 2] = wrap_to_pi(np.arctan2(tform[:, 1, 0], tform[:, 0, 0]))
    return pose


def pose2tform(pose_xytheta: np.ndarray) -> np.ndarray:
    """Planar pose [x y theta] (3,)/(N,3) (metres, radians) -> 3D transform (4,4)/(N,4,4).

    Rotation about z by theta, translation [x y 0].
    """
    tform, single = _planar_tforms(pose_xytheta, 4)
    return unstack(tform, single)


def tform2pose(tform: np.ndarray) -> np.ndarray:
    """3D transform (4,4)/(N,4,4) -> planar pose [x y theta] (3,)/(N,3), theta in (-pi, pi].

    z, roll and pitch are dropped: theta is the yaw of the 'ZYX' Euler angles,
    atan2(R[1,0], R[0,0]), so a transform of a robot on a slope still gives its heading
    (undefined when the x axis points straight up or down; theta is 0 then).
    """
    tform_arr, single = as_stack(tform, "tform", (4, 4))
    check_tforms(tform_arr, "tform", single)
    return unstack(_poses(tform_arr), single)


def pose2tform2d(pose_xytheta: np.ndarray) -> np.ndarray:
    """Planar pose [x y theta] (3,)/(N,3) (metres, radians) -> 2D homogeneous transform (3,3)/(N,3,3).

    [[cos -sin x], [sin cos y], [0 0 1]]: maps 2D points [px py 1] of the posed frame into the reference frame.
    """
    tform, single = _planar_tforms(pose_xytheta, 3)
    return unstack(tform, single)


def tform2d2pose(tform2d: np.ndarray) -> np.ndarray:
    """2D homogeneous transform (3,3)/(N,3,3) -> planar pose [x y theta] (3,)/(N,3), theta in (-pi, pi]."""
    tform_arr, single = as_stack(tform2d, "tform2d", (3, 3))
    check_tforms(tform_arr, "tform2d", single)
    return unstack(_poses(tform_arr), single)


def se2_compose(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Compose planar poses [x, y, theta]: a then b, b expressed in a's frame (T_w_b = T_w_a T_a_b).

    Broadcasts over leading dimensions; theta is a_theta + b_theta, not wrapped.
    """
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    return np.stack([a[..., 0] + c * b[..., 0] - s * b[..., 1], a[..., 1] + s * b[..., 0] + c * b[..., 1],
                     a[..., 2] + b[..., 2]], axis=-1)


def se2_inverse(a: np.ndarray) -> np.ndarray:
    """Inverse of planar poses [x, y, theta] (T_b_a from T_a_b); broadcasts over leading dimensions."""
    a = np.asarray(a, dtype=np.float64)
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    return np.stack([-(c * a[..., 0] + s * a[..., 1]), s * a[..., 0] - c * a[..., 1], -a[..., 2]], axis=-1)


def se2_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Pose of b in a's frame, inverse(a) then b, theta wrapped to (-pi, pi]; broadcasts."""
    d = se2_compose(se2_inverse(a), b)
    d[..., 2] = wrap_to_pi(d[..., 2])
    return d


# Single planar poses in a loop body (a front end's tens of calls per scan): the same as se2_compose and
# se2_between, which the tests compare them with, without numpy's per-call overhead on 3-vectors.
def se2_compose_fast(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """:func:`se2_compose` of two single poses (3,): a then b, theta not wrapped."""
    c, s = math.cos(a[2]), math.sin(a[2])
    return np.array([a[0] + c * b[0] - s * b[1], a[1] + s * b[0] + c * b[1], a[2] + b[2]])


def se2_between_fast(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """:func:`se2_between` of two single poses (3,): b in a's frame, theta wrapped to [-pi, pi)."""
    c, s = math.cos(a[2]), math.sin(a[2])
    dx, dy = b[0] - a[0], b[1] - a[1]
    return np.array([c * dx + s * dy, -s * dx + c * dy, (b[2] - a[2] + math.pi) % (2 * math.pi) - math.pi])
