"""Throughput of the vectorized transforms on a large stack against a per-item Python loop of the same function.

Each row: items per second for one call on a stack of 10^6 (10^5 with --quick),
baseline the same function called once per item on a 5000-item subset
(500 with --quick), scaled to items per second.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy.spatial.transform import Rotation

from bagtools.transforms import eul2rotm, quat2rotm, quatmultiply, rotatepoint, rotm2eul, rotm2quat
from bench.common import Row, best_time_s


def _row(name: str, stack_fn: Callable[[slice], object], item_fn: Callable[[int], object], n_stack: int, n_loop: int) -> Row:
    stack_s = best_time_s(lambda: stack_fn(slice(0, n_stack)))
    loop_s = best_time_s(lambda: [item_fn(i) for i in range(n_loop)])
    return Row(
        capability="transforms",
        measure=f"{name}, stack of {n_stack:.0e}",
        value=n_stack / stack_s,
        unit="items/s",
        baseline=f"{name} called per item in a Python loop ({n_loop} items)",
        baseline_value=n_loop / loop_s,
        higher_is_better=True,
        target=">= 10x the per-item loop",
    )


def run(quick: bool) -> list[Row]:
    """Rows for eul2rotm, rotm2eul, quat2rotm, rotm2quat, quatmultiply and rotatepoint."""
    n_stack, n_loop = (10**5, 500) if quick else (10**6, 5000)
    rng = np.random.default_rng(0)
    eul = rng.uniform(-np.pi, np.pi, size=(n_stack, 3))
    rotm = Rotation.from_euler("ZYX", eul).as_matrix()
    quat = rng.normal(size=(n_stack, 4))
    quat_b = rng.normal(size=(n_stack, 4))
    points = rng.normal(size=(n_stack, 3))
    return [
        _row("eul2rotm", lambda s: eul2rotm(eul[s]), lambda i: eul2rotm(eul[i]), n_stack, n_loop),
        _row("rotm2eul", lambda s: rotm2eul(rotm[s]), lambda i: rotm2eul(rotm[i]), n_stack, n_loop),
        _row("quat2rotm", lambda s: quat2rotm(quat[s]), lambda i: quat2rotm(quat[i]), n_stack, n_loop),
        _row("rotm2quat", lambda s: rotm2quat(rotm[s]), lambda i: rotm2quat(rotm[i]), n_stack, n_loop),
        _row("quatmultiply", lambda s: quatmultiply(quat[s], quat_b[s]), lambda i: quatmultiply(quat[i], quat_b[i]), n_stack, n_loop),
        _row("rotatepoint", lambda s: rotatepoint(quat[s], points[s]), lambda i: rotatepoint(quat[i], points[i]), n_stack, n_loop),
    ]
