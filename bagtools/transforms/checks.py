"""Input checks shared by every ``bagtools.transforms`` function.

Every public function turns its input into a float64 stack with :func:`as_stack`
(one item becomes a stack of one, and the caller reshapes back), then checks
what the representation needs: :func:`check_rotations` for rotation matrices,
:func:`check_tforms` for homogeneous transforms, :func:`check_nonzero` for
quaternions and rotation axes, :func:`check_seq` for Euler sequences. Each
failure is a ``ValueError`` with one line saying which argument is wrong, how,
and (for stacks) at which index.
"""

from __future__ import annotations

import numpy as np

#: Largest |R^T R - I| entry accepted for a rotation matrix (and |bottom row - [0 .. 0 1]| for a transform).
ROTATION_TOL = 1e-6
#: Norm below which a quaternion or a rotation axis counts as zero.
ZERO_NORM_TOL = 1e-12
#: The Euler axis sequences supported, as in MATLAB; all are intrinsic (rotations about the moving axes).
EULER_SEQUENCES = ("ZYX", "ZYZ", "XYZ")


def _shape_text(shape: tuple[int, ...]) -> str:
    """Python's tuple notation without spaces: (3,), (3,4), ()."""
    inner = ",".join(str(n) for n in shape)
    return f"({inner},)" if len(shape) == 1 else f"({inner})"


def _at(index: int, single: bool) -> str:
    return "" if single else f" at index {index}"


def as_stack(value: object, name: str, item_shape: tuple[int, ...]) -> tuple[np.ndarray, bool]:
    """Return ``value`` as a float64 array of shape (N, *item_shape) and whether it was a single item.

    Raises ValueError for non-numeric input, a shape that is neither ``item_shape``
    nor (N, *item_shape), or a NaN/inf entry.
    """
    try:
        raw = np.asarray(value)
    except ValueError as exc:  # ragged nested lists
        raise ValueError(f"{name} must be a numeric array: {exc}") from None
    if raw.dtype.kind not in "iuf":
        raise ValueError(f"{name} must hold real numbers, got dtype {raw.dtype}")
    arr = raw.astype(np.float64, copy=False)
    item = _shape_text(item_shape)
    stack = _shape_text((-1, *item_shape)).replace("-1", "N")
    if arr.shape == item_shape:
        single, arr = True, arr[np.newaxis]
    elif arr.ndim == len(item_shape) + 1 and arr.shape[1:] == item_shape:
        single = False
    else:
        raise ValueError(f"{name} must have shape {item} or {stack}, got {_shape_text(arr.shape)}")
    finite = np.isfinite(arr).all(axis=tuple(range(1, arr.ndim)))
    if not finite.all():
        raise ValueError(f"{name} has a NaN or infinite value{_at(int(np.argmin(finite)), single)}")
    return arr, single


def check_rotations(rotm: np.ndarray, name: str, single: bool) -> None:
    """Raise ValueError unless every (D,D) matrix of the (N,D,D) stack is a rotation.

    A rotation is orthonormal (every entry of R^T R - I within ROTATION_TOL) with
    determinant +1 (not a reflection). Works for D = 2 and D = 3.
    """
    if not len(rotm):
        return
    dim = rotm.shape[-1]
    gram_error = np.abs(np.matmul(rotm.transpose(0, 2, 1), rotm) - np.eye(dim)).max(axis=(1, 2))
    bad = gram_error > ROTATION_TOL
    if bad.any():
        i = int(np.argmax(bad))
        raise ValueError(
            f"{name} is not a rotation matrix{_at(i, single)}: not orthonormal "
            f"(max |R^T R - I| = {gram_error[i]:.3g} > {ROTATION_TOL:g})"
        )
    if dim == 3:
        det = np.einsum("ni,ni->n", rotm[:, :, 0], np.cross(rotm[:, :, 1], rotm[:, :, 2]))
    else:
        det = rotm[:, 0, 0] * rotm[:, 1, 1] - rotm[:, 0, 1] * rotm[:, 1, 0]
    bad = det < 0
    if bad.any():
        i = int(np.argmax(bad))
        raise ValueError(f"{name} is not a rotation matrix{_at(i, single)}: determinant is {det[i]:.3g} (a reflection), not +1")


def check_tforms(tform: np.ndarray, name: str, single: bool) -> None:
    """Raise ValueError unless every (D+1,D+1) matrix of the stack is a rigid homogeneous transform.

    The top-left (D,D) block must be a rotation (see :func:`check_rotations`) and
    the bottom row [0 .. 0 1] within ROTATION_TOL.
    """
    if not len(tform):
        return
    size = tform.shape[-1]
    bottom = np.zeros(size)
    bottom[-1] = 1.0
    row_error = np.abs(tform[:, -1, :] - bottom).max(axis=1)
    bad = row_error > ROTATION_TOL
    if bad.any():
        i = int(np.argmax(bad))
        expected = "[" + " ".join(f"{v:g}" for v in bottom) + "]"
        raise ValueError(f"{name} is not a homogeneous transform{_at(i, single)}: bottom row is not {expected}")
    check_rotations(tform[:, :-1, :-1], f"{name} rotation part", single)


def check_nonzero(vectors: np.ndarray, name: str, single: bool, what: str) -> np.ndarray:
    """Return the norms of the (N,K) ``vectors``; raise ValueError if any is below ZERO_NORM_TOL.

    ``what`` names the thing for the message, e.g. "quaternion" or "rotation axis".
    """
    norms = np.sqrt(np.einsum("ni,ni->n", vectors, vectors))
    bad = norms < ZERO_NORM_TOL
    if bad.any():
        i = int(np.argmax(bad))
        raise ValueError(f"{name} has a zero {what}{_at(i, single)} (norm {norms[i]:.3g}): it does not describe a rotation")
    return norms


def check_seq(seq: object) -> str:
    """Return the Euler sequence ``seq`` in upper case; raise ValueError if it is not one of EULER_SEQUENCES.

    Case does not matter, as in MATLAB: 'zyx' means the intrinsic 'ZYX' (unlike
    scipy, where lower case means extrinsic).
    """
    if isinstance(seq, str) and seq.upper() in EULER_SEQUENCES:
        return seq.upper()
    choices = ", ".join(repr(s) for s in EULER_SEQUENCES)
    raise ValueError(f"unknown Euler sequence {seq!r}: use one of {choices}")


def check_same_count(count_a: int, name_a: str, count_b: int, name_b: str) -> None:
    """Raise ValueError when two stacks that are paired item by item have different lengths (1 broadcasts)."""
    if count_a != count_b and count_a != 1 and count_b != 1:
        raise ValueError(f"{name_a} has {count_a} items but {name_b} has {count_b}: give equal counts, or one item to apply to all")
