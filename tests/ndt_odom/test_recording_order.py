"""Scans stamped out of the order they were recorded in (ROS 1 header.seq): registered in recording order, each
posed at its own stamp, as the Intel Research Lab log needs (631 scans stamped up to 0.9 s early)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from rosbags.rosbag1 import Writer
from rosbags.typesys import Stores, get_typestore

from bagtools.dataset import recording_order, stamped_late
from bagtools.commands.ndt_odom import NdtOdomOptions, NdtOdomPipeline
from bagtools.transforms import se2_between, tform2pose
from bagtools_simulate.sensors.lidar import Lidar
from bagtools_simulate.world import load_world

ROS1 = get_typestore(Stores.ROS1_NOETIC)


def test_recording_order_is_the_seq_order_when_it_moves_scans_a_little() -> None:
    stamps = np.array([10, 20, 25, 30, 40, 50])  # as read: stamp order
    order = recording_order(stamps, [0, 1, 3, 2, 4, 5])  # the scan stamped 25 was recorded after the one at 30
    assert order is not None and order.tolist() == [0, 1, 3, 2, 4, 5]
    assert stamps[order].tolist() == [10, 20, 30, 25, 40, 50]


def test_stamped_late_marks_what_is_stamped_before_something_recorded_earlier() -> None:
    stamps = np.array([10, 20, 25, 30, 40, 50])
    order = np.array([0, 1, 3, 2, 4, 5])  # recorded: 10, 20, 30, 25, 40, 50
    assert stamped_late(stamps, order).tolist() == [False, False, True, False, False, False]


@pytest.mark.parametrize("seqs", [
    [None] * 6,  # ROS 2: no seq
    [0, 1, 2, 3, 4, 5],  # nothing out of order
    [0, 1, 1, 2, 3, 4],  # two publishers, or a repeated number: not a recording order
])
def test_recording_order_is_none_without_a_usable_seq(seqs: list) -> None:
    assert recording_order(np.arange(6) * 10, seqs) is None


def test_a_publisher_restart_is_no_recording_order() -> None:
    """A node restarted half way numbers from 0 again: seq order would put the second half first."""
    n = 400
    seqs = list(range(200)) + list(range(200))
    seqs[10], seqs[11] = seqs[11], seqs[10]
    assert recording_order(np.arange(n), seqs) is None


def _ros1_scan_bag(path: Path, stamps_ns: np.ndarray, seqs: list[int], poses: np.ndarray, lidar: Lidar) -> Path:
    """A ROS 1 bag of LaserScans of the TurtleBot3 world from base poses ``poses`` (N,3), in stamp order."""
    world = load_world("turtlebot3_world")
    rng = np.random.default_rng(0)
    T = ROS1.types
    with Writer(path) as writer:
        conn = writer.add_connection("/scan", "sensor_msgs/msg/LaserScan", typestore=ROS1)
        for k in np.argsort(stamps_ns, kind="stable"):
            x, y, yaw = poses[k]
            ranges = lidar.scan(world, (x, y, 0.2, yaw), rng)
            stamp = int(stamps_ns[k])
            header = T["std_msgs/msg/Header"](seq=int(seqs[k]), stamp=T["builtin_interfaces/msg/Time"](
                sec=stamp // 1_000_000_000, nanosec=stamp % 1_000_000_000), frame_id="base_scan")
            msg = T["sensor_msgs/msg/LaserScan"](
                header=header, angle_min=lidar.angle_min_rad,
                angle_max=lidar.angle_min_rad + lidar.angle_increment_rad * (len(ranges) - 1),
                angle_increment=lidar.angle_increment_rad, time_increment=0.0, scan_time=0.2, range_min=0.12,
                range_max=3.5, ranges=np.asarray(ranges, dtype=np.float32), intensities=np.zeros(0, np.float32))
            writer.write(conn, stamp, ROS1.serialize_ros1(msg, "sensor_msgs/msg/LaserScan"))
    return path


def test_scans_stamped_before_their_predecessor_are_registered_in_recording_order(tmp_path: Path, lap_truth) -> None:
    """A 180-degree laser, a scan every 0.27 s, and every third scan stamped 0.9 of a step before the scan recorded
    before it, as in the Intel log. In stamp order the robot jumps back and forth, and the front end ends 2.3 m and
    69 degrees off; in recording order (seq) every scan is posed right (7 cm, 2 degrees), at its own stamp."""
    stamps, T_map_base = lap_truth
    keep = np.arange(0, len(stamps), 8)
    true_stamps, poses = stamps[keep], tform2pose(T_map_base[keep])
    bag_stamps = true_stamps.copy()
    early = np.arange(3, len(keep), 3)
    bag_stamps[early] = true_stamps[early - 1] - (0.9 * np.diff(true_stamps).mean()).astype(np.int64)
    lidar = Lidar(samples=181, angle_min_rad=-np.pi / 2, angle_max_rad=np.pi / 2)
    bag = _ros1_scan_bag(tmp_path / "early.bag", bag_stamps, list(range(len(keep))), poses, lidar)
    result = NdtOdomPipeline(bag, NdtOdomOptions()).run()
    s = result.summary
    assert s["scans_used"] == len(keep) and s["scans_out_of_recording_order"] == len(early)
    assert any("stamped before the scan recorded before them" in w for w in s["warnings"])
    traj = result.trajectory
    assert np.all(np.diff(traj.stamps_ns) > 0)  # the trajectory is in stamp order, a pose at every scan's stamp
    at = {int(t): k for k, t in enumerate(bag_stamps)}
    estimate = tform2pose(traj.poses)
    truth = poses[[at[int(t)] for t in traj.stamps_ns]]
    # both relative to the first scan (recorded and stamped first)
    err = se2_between(se2_between(truth[0], truth), se2_between(estimate[0], estimate))
    assert np.hypot(err[:, 0], err[:, 1]).max() < 0.15 and np.abs(err[:, 2]).max() < np.radians(5.0)
