"""Rotation and transform conversions with MATLAB Robotics System Toolbox names and conventions.

Conventions (as MATLAB's, except the stack layout):

- Quaternions are scalar first, ``[w x y z]``. At the ROS boundary (``x y z w``)
  convert with :func:`xyzw2quat` / :func:`quat2xyzw`.
- Euler angles are radians in the order of ``seq``: ``'ZYX'`` (default), ``'ZYZ'``
  or ``'XYZ'`` (case-insensitive, always intrinsic as in MATLAB):
  ``eul2rotm([a b c], 'ZYX') == Rz(a) @ Ry(b) @ Rx(c)``. ``rotm2eul`` returns
  the first and third angle in [-pi, pi], the middle one in [-pi/2, pi/2]
  (``'ZYX'``, ``'XYZ'``) or [-pi, 0] (``'ZYZ'``); at gimbal lock the first angle
  is 0 and the third carries the combined rotation.
- Axis-angle is ``[x y z theta]``, theta in radians; the axis is normalized on input.
- ``rotm2quat``/``tform2quat`` return w >= 0. Conversions from a quaternion
  normalize it first; ``quatinv`` is conj(q) / |q|^2.
- Rotation matrices act on column vectors (premultiply), ``p_a = R_a_b @ p_b``.
- Homogeneous transforms are 4x4; ``T_a_b`` maps points from frame b into frame a.

Stacks are numpy-natural, not MATLAB's 3x3xN: one item or a stack along the
first axis, and the output matches (one in, one out; N in, N out):

======  ===============  ==========================
name    one item         stack
======  ===============  ==========================
rotm    (3, 3)           (N, 3, 3)
tform   (4, 4)           (N, 4, 4)
trvec   (3,)             (N, 3)      metres
quat    (4,)             (N, 4)      [w x y z]
eul     (3,)             (N, 3)      radians
axang   (4,)             (N, 4)      [x y z theta]
pose    (3,)             (N, 3)      [x y theta], metres and radians
======  ===============  ==========================

Every function is vectorized over the stack. Bad input raises ``ValueError``
with one line naming the argument and the problem: wrong shape, NaN/inf, a
matrix that is not a rotation (orthonormal within 1e-6 and det +1), a transform
whose bottom row is not [0 0 0 1], a zero quaternion or rotation axis, an
unknown Euler sequence.

Planar helpers: :func:`pose2tform`/:func:`tform2pose` between [x y theta] and
4x4 transforms, :func:`pose2tform2d`/:func:`tform2d2pose` for 3x3 2D homogeneous
transforms, and :func:`wrap_to_pi` (to (-pi, pi]).

scipy (whose ``scipy.spatial`` takes ~0.2 s to import) is imported by the functions
that use its ``Rotation``, on first call; the planar helpers and the quaternion
algebra (``quatmultiply``, ``quatconj``, ``quatinv``, ``axang2quat``, ``quat2axang``,
``xyzw2quat``, ``quat2xyzw``) never import it.
"""

from bagtools.transforms.axisangle import axang2rotm, axang2tform, rotm2axang, tform2axang
from bagtools.transforms.checks import EULER_SEQUENCES, ROTATION_TOL
from bagtools.transforms.planar import (
    pose2tform,
    pose2tform2d,
    se2_between,
    se2_compose,
    se2_inverse,
    tform2d2pose,
    tform2pose,
    wrap_to_pi,
)
from bagtools.transforms.quaternions import (
    axang2quat,
    eul2quat,
    quat2axang,
    quat2eul,
    quat2rotm,
    quat2tform,
    quat2xyzw,
    quatconj,
    quatinv,
    quatmultiply,
    rotatepoint,
    rotm2quat,
    tform2quat,
    xyzw2quat,
)
from bagtools.transforms.rotations import (
    eul2rotm,
    eul2tform,
    rotm2eul,
    rotm2tform,
    tform2eul,
    tform2rotm,
    tform2trvec,
    trvec2tform,
)

__all__ = [
    "EULER_SEQUENCES",
    "ROTATION_TOL",
    "axang2quat",
    "axang2rotm",
    "axang2tform",
    "eul2quat",
    "eul2rotm",
    "eul2tform",
    "pose2tform",
    "pose2tform2d",
    "quat2axang",
    "quat2eul",
    "quat2rotm",
    "quat2tform",
    "quat2xyzw",
    "quatconj",
    "quatinv",
    "quatmultiply",
    "rotatepoint",
    "rotm2axang",
    "rotm2eul",
    "rotm2quat",
    "rotm2tform",
    "se2_between",
    "se2_compose",
    "se2_inverse",
    "tform2axang",
    "tform2d2pose",
    "tform2eul",
    "tform2pose",
    "tform2quat",
    "tform2rotm",
    "tform2trvec",
    "trvec2tform",
    "wrap_to_pi",
    "xyzw2quat",
]
