"""Independent references for the transforms tests: elementary rotations written out by hand."""

from __future__ import annotations

import numpy as np
import pytest


def rot_x(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rot_y(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rot_z(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


ELEMENTARY = {"X": rot_x, "Y": rot_y, "Z": rot_z}


def intrinsic(eul: np.ndarray, seq: str) -> np.ndarray:
    """R = R_seq[0](eul[0]) @ R_seq[1](eul[1]) @ R_seq[2](eul[2]) for one Euler triple."""
    return ELEMENTARY[seq[0]](eul[0]) @ ELEMENTARY[seq[1]](eul[1]) @ ELEMENTARY[seq[2]](eul[2])


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20240607)


def random_quats(rng: np.random.Generator, n: int) -> np.ndarray:
    """n random unit quaternions [w x y z], both signs of w."""
    q = rng.normal(size=(n, 4))
    return q / np.linalg.norm(q, axis=1, keepdims=True)
