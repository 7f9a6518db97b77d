"""Vectorized rigid motions as (quaternion, translation) pairs, component-first.

Private to :mod:`bagtools.tf`: the buffer's hot path. Quaternions are ROS order
x, y, z, w stored as (4, N) arrays (component first, so every component is a
contiguous row); translations are (3, N) metres. An item may also be (4, 1) /
(3, 1) and broadcasts (a static transform against N stamps). ``None`` stands
for the identity. scipy's Rotation is avoided here on purpose: its composition
of 10^6 rotations costs ~0.5 s, ten times these plain numpy expressions.
"""

from __future__ import annotations

import math

import numpy as np

Rigid = tuple[np.ndarray, np.ndarray] | None  # (q_xyzw (4,N), t (3,N)) or identity


def quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product a * b of x, y, z, w quaternions (4, N) each (or (4, 1), broadcast)."""
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return np.stack((
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
        aw * bw - ax * bx - ay * by - az * bz,
    ))


def quat_rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate vectors v (3, N) by unit quaternions q (4, N) x, y, z, w: q v q*."""
    qx, qy, qz, qw = q
    vx, vy, vz = v
    # t = 2 (u x v); v' = v + w t + u x t
    tx = 2.0 * (qy * vz - qz * vy)
    ty = 2.0 * (qz * vx - qx * vz)
    tz = 2.0 * (qx * vy - qy * vx)
    return np.stack((
        vx + qw * tx + (qy * tz - qz * ty),
        vy + qw * ty + (qz * tx - qx * tz),
        vz + qw * tz + (qx * ty - qy * tx),
    ))


def quat_conj(q: np.ndarray) -> np.ndarray:
    """Conjugate (the inverse of a unit quaternion), x, y, z, w."""
    return np.stack((-q[0], -q[1], -q[2], q[3]))


def compose(a: Rigid, b: Rigid) -> Rigid:
    """a ∘ b: if a = T_x_y and b = T_y_z, the result is T_x_z."""
    if a is None:
        return b
    if b is None:
        return a
    qa, ta = a
    qb, tb = b
    return quat_mul(qa, qb), quat_rotate(qa, tb) + ta


def inverse(a: Rigid) -> Rigid:
    """T_y_x from T_x_y."""
    if a is None:
        return None
    q_inv = quat_conj(a[0])
    return q_inv, -quat_rotate(q_inv, a[1])


def take(a: Rigid, index: np.ndarray) -> Rigid:
    """The items ``index`` (int or bool array) of a stack; broadcast (…, 1) items stay as they are."""
    if a is None:
        return None
    q, t = a
    if q.shape[1] == 1:
        return a
    return q[:, index], t[:, index]


def to_matrices(a: Rigid, n: int) -> np.ndarray:
    """(n, 4, 4) homogeneous matrices [R t; 0 1] of a stack of n items (or one broadcast item)."""
    out = np.zeros((n, 4, 4))
    out[:, 3, 3] = 1.0
    if a is None:
        out[:, 0, 0] = out[:, 1, 1] = out[:, 2, 2] = 1.0
        return out
    q, t = a
    if q.shape[1] == 1:
        out[:] = _fill_matrices(np.zeros((1, 4, 4)), q, t)
        out[:, 3, 3] = 1.0
        return out
    # Blocks small enough to stay in cache: the (n,4,4) layout makes every write strided.
    for start in range(0, n, _BLOCK):
        stop = min(start + _BLOCK, n)
        _fill_matrices(out[start:stop], q[:, start:stop], t[:, start:stop])
    return out


_BLOCK = 1 << 12


def _fill_matrices(out: np.ndarray, q: np.ndarray, t: np.ndarray) -> np.ndarray:
    x, y, z, w = q
    xx, yy, zz = x * x, y * y, z * z
    xy, xz, yz = x * y, x * z, y * z
    wx, wy, wz = w * x, w * y, w * z
    out[:, 0, 0] = 1.0 - 2.0 * (yy + zz)
    out[:, 0, 1] = 2.0 * (xy - wz)
    out[:, 0, 2] = 2.0 * (xz + wy)
    out[:, 1, 0] = 2.0 * (xy + wz)
    out[:, 1, 1] = 1.0 - 2.0 * (xx + zz)
    out[:, 1, 2] = 2.0 * (yz - wx)
    out[:, 2, 0] = 2.0 * (xz - wy)
    out[:, 2, 1] = 2.0 * (yz + wx)
    out[:, 2, 2] = 1.0 - 2.0 * (xx + yy)
    out[:, :3, 3] = t.T
    return out


def slerp_weights(alpha: np.ndarray, theta_over_pi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Shortest-path slerp weights (w0, w1) for fractions ``alpha`` and half-angles θ/π between the ends.

    w0 = sin((1-α)θ)/sin θ and w1 = sin(αθ)/sin θ written with sinc, so θ = 0
    gives the linear weights; α = 0 and α = 1 give exactly (1, 0) and (0, 1).
    """
    sinc_theta = np.sinc(theta_over_pi)
    w0 = (1.0 - alpha) * np.sinc((1.0 - alpha) * theta_over_pi) / sinc_theta
    w1 = alpha * np.sinc(alpha * theta_over_pi) / sinc_theta
    return w0, w1


# -- one item on plain floats ------------------------------------------------------------------
# The same formulas as above for one (q, t) pair of Python floats: a single tf lookup per call costs
# microseconds here against tens of microseconds of numpy call overhead.


def quat_mul_one(a, b) -> tuple[float, float, float, float]:
    """:func:`quat_mul` of two x, y, z, w quaternions given as 4 floats."""
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return (aw * bx + ax * bw + ay * bz - az * by, aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw, aw * bw - ax * bx - ay * by - az * bz)


def quat_rotate_one(q, v) -> tuple[float, float, float]:
    """:func:`quat_rotate` of one vector (3 floats) by one unit quaternion (4 floats)."""
    qx, qy, qz, qw = q
    vx, vy, vz = v
    tx, ty, tz = 2.0 * (qy * vz - qz * vy), 2.0 * (qz * vx - qx * vz), 2.0 * (qx * vy - qy * vx)
    return (vx + qw * tx + (qy * tz - qz * ty), vy + qw * ty + (qz * tx - qx * tz), vz + qw * tz + (qx * ty - qy * tx))


def compose_one(a, b):
    """:func:`compose` of two (q, t) pairs of floats: T_x_z from T_x_y and T_y_z."""
    (qa, ta), (qb, tb) = a, b
    r = quat_rotate_one(qa, tb)
    return quat_mul_one(qa, qb), (r[0] + ta[0], r[1] + ta[1], r[2] + ta[2])


def inverse_one(a):
    """:func:`inverse` of one (q, t) pair of floats."""
    q, t = a
    q_inv = (-q[0], -q[1], -q[2], q[3])
    r = quat_rotate_one(q_inv, t)
    return q_inv, (-r[0], -r[1], -r[2])


def slerp_weights_one(alpha: float, theta_over_pi: float) -> tuple[float, float]:
    """:func:`slerp_weights` for one fraction and half-angle, with numpy's sinc."""
    sinc_theta = _sinc_one(theta_over_pi)
    return ((1.0 - alpha) * _sinc_one((1.0 - alpha) * theta_over_pi) / sinc_theta,
            alpha * _sinc_one(alpha * theta_over_pi) / sinc_theta)


def _sinc_one(x: float) -> float:
    """numpy's sinc on one float: sin(pi x) / (pi x), x = 0 taken as 1e-20 as numpy does."""
    y = math.pi * (x if x != 0.0 else 1.0e-20)
    return math.sin(y) / y


def matrix_one(a) -> np.ndarray:
    """The (4, 4) matrix [R t; 0 1] of one (q, t) pair of floats, as :func:`to_matrices` fills it."""
    (x, y, z, w), t = a
    xx, yy, zz, xy, xz, yz = x * x, y * y, z * z, x * y, x * z, y * z
    wx, wy, wz = w * x, w * y, w * z
    return np.array([[1.0 - 2.0 * (yy + zz), 2.0 * (xy - wz), 2.0 * (xz + wy), t[0]],
                     [2.0 * (xy + wz), 1.0 - 2.0 * (xx + zz), 2.0 * (yz - wx), t[1]],
                     [2.0 * (xz - wy), 2.0 * (yz + wx), 1.0 - 2.0 * (xx + yy), t[2]],
                     [0.0, 0.0, 0.0, 1.0]])
