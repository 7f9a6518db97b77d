"""Bags for the laser-odometry tests: simulated laps and hand-built scan bags."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from bagtools.io import open_bag
from bagtools.simtruth import read_ground_truth
from bagtools.transforms import quat2xyzw, tform2pose, tform2quat
from bagtools_simulate.sensors.lidar import Lidar
from bagtools_simulate.world import load_world
from tests.conftest import FIXTURES, TYPESTORE, _header, make_scan, make_tf, write_bag

T0_NS = 1_700_000_000_000_000_000


def make_odometry(stamp_ns: int, parent: str, child: str, T: np.ndarray):
    """A nav_msgs/Odometry with the pose T (4x4) of ``child`` in ``parent``."""
    types = TYPESTORE.types
    q = quat2xyzw(tform2quat(T))
    pose = types["geometry_msgs/msg/Pose"](
        position=types["geometry_msgs/msg/Point"](x=T[0, 3], y=T[1, 3], z=T[2, 3]),
        orientation=types["geometry_msgs/msg/Quaternion"](x=q[0], y=q[1], z=q[2], w=q[3]))
    zero = types["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)
    return types["nav_msgs/msg/Odometry"](
        header=_header(stamp_ns, parent), child_frame_id=child,
        pose=types["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=np.zeros(36)),
        twist=types["geometry_msgs/msg/TwistWithCovariance"](
            twist=types["geometry_msgs/msg/Twist"](linear=zero, angular=zero), covariance=np.zeros(36)))


@pytest.fixture(scope="session")
def lap_truth() -> tuple[np.ndarray, np.ndarray]:
    """Stamps and true base poses (N,4,4) of the 20 s simulated lap fixture."""
    with open_bag(FIXTURES / "sim_lap_cloud_20s") as bag:
        stamps, T, _ = read_ground_truth(bag)
    return stamps, T


def scan_bag(path: Path, stamps_ns: np.ndarray, T_map_scan: np.ndarray, lidar: Lidar, with_truth: bool = True,
             seed: int = 0) -> Path:
    """A bag of LaserScans of the TurtleBot3 world seen from poses T_map_scan, no odometry, no tf.

    With ``with_truth`` it also carries /ground_truth: the pose of base_scan in map.
    """
    world = load_world("turtlebot3_world")
    rng = np.random.default_rng(seed)
    msgs = []
    for stamp, T in zip(stamps_ns, T_map_scan):
        x, y, yaw = tform2pose(T)
        ranges = lidar.scan(world, (x, y, 0.2, yaw), rng)
        msgs.append(("/scan", "sensor_msgs/msg/LaserScan", int(stamp) + 20_000_000,
                     make_scan(int(stamp), ranges, lidar.angle_min_rad, lidar.angle_increment_rad)))
        if with_truth:
            msgs.append(("/ground_truth", "nav_msgs/msg/Odometry", int(stamp) + 1_000_000,
                         make_odometry(int(stamp), "map", "base_scan", T)))
    msgs.sort(key=lambda m: m[2])
    return write_bag(path, msgs)


__all__ = ["T0_NS", "make_odometry", "make_scan", "make_tf", "scan_bag", "write_bag"]
