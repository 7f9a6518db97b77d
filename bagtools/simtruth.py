"""The truth recorded in bags written by ``bagtools simulate``.

A simulated bag carries its world geometry and simulator configuration as JSON in
a std_msgs/String on ``/simulation/world``. Commands that can score their output
against the truth (map-cloud, grid, ndt-odom) load it from here. The poses a bag
records of its robot (a reference on ``/ground_truth``, a localizer's
``/amcl_pose``) are read here too (:func:`read_poses`).
"""

from __future__ import annotations

import json
from typing import TYPE_CHECKING, Any

import numpy as np

from bagtools.errors import BagError
from bagtools.io import (
    ODOMETRY_TYPES, POSE_WITH_COVARIANCE_TYPES, BagReader, decode_odometry, decode_pose_with_covariance,
)
from bagtools.transforms import quat2tform, xyzw2quat

if TYPE_CHECKING:
    from bagtools_simulate.world import World

SIM_WORLD_TOPIC = "/simulation/world"
GROUND_TRUTH_TOPIC = "/ground_truth"


def read_sim_info(bag: BagReader) -> dict[str, Any] | None:
    """The JSON document of ``/simulation/world`` ({"world", "config", "robot"}), or None for other bags."""
    if SIM_WORLD_TOPIC not in bag.topics:
        return None
    try:
        record = next(bag.messages([SIM_WORLD_TOPIC]), None)
    except BagError:  # lost to damage (said among the bag's warnings): what needs only the bag goes on without it
        return None
    if record is None:
        return None
    try:
        return json.loads(record.msg.data)
    except (json.JSONDecodeError, AttributeError) as err:
        raise BagError(f"{SIM_WORLD_TOPIC} does not hold the simulator's JSON: {err}", bag.path) from err


def load_sim_world(bag: BagReader) -> World | None:
    """The true world of a simulated bag, or None when the bag is not simulated."""
    info = read_sim_info(bag)
    if info is None or "world" not in info:
        return None
    from bagtools_simulate.world import World

    return World.from_dict(info["world"], path=bag.path)


#: A reference moving faster than this (m/s), plus the floor (m), between two samples has jumped (a reset, a
#: relocalization, damage): no mobile robot the tools are for drives that fast.
GROUND_TRUTH_MAX_SPEED_MPS, GROUND_TRUTH_JUMP_FLOOR_M = 20.0, 1.0


def read_poses(bag: BagReader, topic: str,
               warnings: list[str] | None = None) -> tuple[np.ndarray, np.ndarray, str, str] | None:
    """The poses recorded on ``topic``: (stamps_ns (N,), T_frame_body (N,4,4), frame id, child frame id ("" for a
    PoseWithCovarianceStamped, which names none)), in stamp order, or None.

    Read from nav_msgs/Odometry (a reference, /ground_truth) or geometry_msgs/PoseWithCovarianceStamped (AMCL's
    /amcl_pose). Samples with a non-finite value, a quaternion far from unit length or a stamp seen before are
    dropped, and said in ``warnings`` when given; None when the topic has no such messages or no sample is left.
    """
    if topic not in bag.topics:
        return None
    msgtype = bag.topics[topic].msgtype
    if msgtype not in ODOMETRY_TYPES + POSE_WITH_COVARIANCE_TYPES:
        if warnings is not None:
            warnings.append(f"{topic} has type {msgtype}, not nav_msgs/Odometry or "
                            "geometry_msgs/PoseWithCovarianceStamped: its poses are not read")
        return None
    decode = decode_odometry if msgtype in ODOMETRY_TYPES else decode_pose_with_covariance
    samples = [decode(rec.msg) for rec in bag.messages([topic])]
    if not samples:
        return None
    stamps = np.array([s.stamp_ns for s in samples], dtype=np.int64)
    xyz = np.array([s.position_m for s in samples])
    q = np.array([s.orientation_xyzw for s in samples])
    with np.errstate(invalid="ignore", over="ignore"):
        ok = (np.isfinite(xyz).all(axis=1) & (np.abs(xyz) <= 1e6).all(axis=1) & np.isfinite(q).all(axis=1)
              & (np.abs(np.linalg.norm(q, axis=1) - 1) < 0.01))
    order = np.flatnonzero(ok)[np.argsort(stamps[ok], kind="stable")]
    order = order[np.r_[True, np.diff(stamps[order]) > 0]] if order.size else order
    if warnings is not None and order.size < len(samples):
        warnings.append(f"{topic}: dropped {len(samples) - order.size} of {len(samples)} poses (non-finite or beyond "
                        "1e6 m, not a unit quaternion, or a repeated stamp)")
    if order.size == 0:
        return None
    T = quat2tform(xyzw2quat(q[order] / np.linalg.norm(q[order], axis=1, keepdims=True)))
    T[:, :3, 3] = xyz[order]
    return stamps[order], T, samples[0].frame_id, getattr(samples[0], "child_frame_id", "")


def read_ground_truth(bag: BagReader, topic: str = GROUND_TRUTH_TOPIC,
                      warnings: list[str] | None = None) -> tuple[np.ndarray, np.ndarray, str] | None:
    """The reference poses of a bag: (stamps_ns (N,), T_map_base (N,4,4), child frame id), or None.

    Read from nav_msgs/Odometry on ``topic`` (the pose of the base in map), as :func:`read_poses` reads it;
    jumps faster than ``GROUND_TRUTH_MAX_SPEED_MPS`` are said in ``warnings`` when given.
    """
    if topic not in bag.topics or bag.topics[topic].msgtype not in ODOMETRY_TYPES:
        return None
    poses = read_poses(bag, topic, warnings)
    if poses is None:
        return None
    stamps, T, _, child = poses
    if warnings is not None and len(stamps) > 1:
        step_m = np.linalg.norm(np.diff(T[:, :3, 3], axis=0), axis=1)
        dt_s = np.diff(stamps) / 1e9
        jumps = np.flatnonzero(step_m > GROUND_TRUTH_MAX_SPEED_MPS * dt_s + GROUND_TRUTH_JUMP_FLOOR_M)
        if jumps.size:
            k = int(jumps[np.argmax(step_m[jumps])])
            warnings.append(f"{topic}: the reference jumps {jumps.size} time(s), up to {step_m[k]:.3g} m in "
                            f"{dt_s[k]:.3g} s (at {stamps[k + 1] / 1e9:.3f} s): faster than "
                            f"{GROUND_TRUTH_MAX_SPEED_MPS:g} m/s, no robot's motion; errors against it are not the "
                            "estimate's")
    return stamps, T, child


def anchor_frame_in_map(T_map_base: np.ndarray, T_frame_base: np.ndarray, valid: np.ndarray) -> tuple[np.ndarray, int] | None:
    """Where a drifting frame (odom, say) really was: T_map_frame (4,4) and the sample it was anchored at.

    Given the true base poses T_map_base (N,4,4) and the same base's poses in the
    frame, T_frame_base (N,4,4), at the same N stamps (``valid`` (N,) bool marks
    which of the latter are known), the frame is placed so that the two agree at
    the first valid stamp: T_map_frame = T_map_base[i] @ inv(T_frame_base[i]).
    What remains between them afterwards is the frame's drift, not its arbitrary
    origin. None when no stamp is valid.
    """
    valid = np.asarray(valid, dtype=bool)
    if not valid.any():
        return None
    first = int(np.flatnonzero(valid)[0])
    return T_map_base[first] @ np.linalg.inv(T_frame_base[first]), first
