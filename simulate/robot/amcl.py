"""An AMCL-like map -> odom publisher: a noisy localization estimate, updated only after motion.

Like nav2's AMCL, the filter updates only after the robot moved ``update_min_d`` or turned
``update_min_a`` since the last update (the issue asks for 0.2 m / 0.5 rad; nav2's defaults are
0.25 m / 0.2 rad), and between updates it republishes the last map -> odom on every scan, stamped
``transform_tolerance`` in the future (nav2's default is 1.0 s). The estimate is the true pose
plus a fresh error of a few centimetres and about a degree at each update.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bagtools_simulate.robot.kinematics import wrap_angle
from bagtools.transforms import se2_compose, se2_inverse

UPDATE_MIN_D_M = 0.2
UPDATE_MIN_A_RAD = 0.5
TRANSFORM_TOLERANCE_NS = 1_000_000_000
ESTIMATE_XY_SD_M = 0.03
ESTIMATE_YAW_SD_RAD = np.deg2rad(1.0)


@dataclass(frozen=True)
class MapToOdom:
    """map -> odom at each scan: ``poses`` (K, 3) [x, y, yaw] of odom in map; ``updated`` (K,) bool."""

    poses: np.ndarray
    updated: np.ndarray


def amcl_map_to_odom(truth_map_base: np.ndarray, odom_base: np.ndarray, rng: np.random.Generator) -> MapToOdom:
    """map -> odom at K scan times from the true poses (K, 3) in map and odometry poses (K, 3) in odom.

    The first scan always updates (AMCL's initial pose). The loop runs once per update, not per scan.
    """
    k_total = len(truth_map_base)
    update_idx: list[int] = []
    i = 0
    while i < k_total:
        update_idx.append(i)
        moved = np.hypot(odom_base[i + 1 :, 0] - odom_base[i, 0], odom_base[i + 1 :, 1] - odom_base[i, 1])
        turned = np.abs(wrap_angle(odom_base[i + 1 :, 2] - odom_base[i, 2]))
        hit = np.flatnonzero((moved >= UPDATE_MIN_D_M) | (turned >= UPDATE_MIN_A_RAD))
        if len(hit) == 0:
            break
        i = i + 1 + int(hit[0])
    idx = np.asarray(update_idx)
    error = np.column_stack(
        [rng.normal(0.0, ESTIMATE_XY_SD_M, (len(idx), 2)), rng.normal(0.0, ESTIMATE_YAW_SD_RAD, len(idx))]
    )
    estimate = truth_map_base[idx] + error
    at_update = se2_compose(estimate, se2_inverse(odom_base[idx]))
    updated = np.zeros(k_total, dtype=bool)
    updated[idx] = True
    held = np.cumsum(updated) - 1  # index of the latest update at or before each scan
    return MapToOdom(at_update[held], updated)
