"""CARMEN logs read natively: every /scan of a log opened and decoded, against the same scans in a ROS 1 bag.

A synthetic FLASER log (180 beams, odometry on every line, the Intel log's
13 631 lines; 2000 with --quick) and a ROS 1 bag holding the same LaserScans.
The value is bagtools' time to open the log and decode every scan (the text
parsed into messages); the baseline is bagtools' time for the same on the ROS
1 bag (rosbags' binary deserialization). Target: at least a quarter of the
binary bag's rate (text is parsed, binary is not): the longest benchmark log read in
seconds, never converted.
"""

from __future__ import annotations

import math
import tempfile
from pathlib import Path

import numpy as np

from bench.common import Row, best_time_s


def _write(directory: Path, n: int) -> tuple[Path, Path]:
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore

    rng = np.random.default_rng(3)
    store = get_typestore(Stores.ROS1_NOETIC)
    T = store.types
    log, bag = directory / "run.clf", directory / "run.bag"
    with log.open("w") as f, Writer(bag) as writer:
        conn = writer.add_connection("/scan", "sensor_msgs/msg/LaserScan", typestore=store)
        for k in range(n):
            ranges = np.round(rng.uniform(0.5, 20.0, 180), 2)
            sec, nsec = 1000 + k // 5, (k % 5) * 200_000_000
            stamp = f"{sec}.{nsec // 1000:06d}"
            f.write(f"FLASER 180 {' '.join(f'{r:.2f}' for r in ranges)} {0.1 * k:.6f} 0 0 {0.1 * k:.6f} 0 0 "
                    f"{stamp} nohost {stamp}\n")
            msg = T["sensor_msgs/msg/LaserScan"](
                header=T["std_msgs/msg/Header"](seq=k, stamp=T["builtin_interfaces/msg/Time"](sec=sec, nanosec=nsec),
                                                frame_id="laser"),
                angle_min=-math.pi / 2, angle_max=math.radians(89), angle_increment=math.pi / 180, time_increment=0.0,
                scan_time=0.0, range_min=0.001, range_max=81.83, ranges=ranges.astype(np.float32),
                intensities=np.zeros(0, np.float32))
            writer.write(conn, sec * 1_000_000_000 + nsec, store.serialize_ros1(msg, "sensor_msgs/msg/LaserScan"))
    return log, bag


def _read(path: Path) -> int:
    from bagtools.io import decode_laserscan, open_bag

    with open_bag(path) as bag:
        return sum(decode_laserscan(rec.msg).ranges_m.size > 0 for rec in bag.messages(["/scan"]))


def run(quick: bool) -> list[Row]:
    n = 2000 if quick else 13_631
    with tempfile.TemporaryDirectory() as tmp:
        log, bag = _write(Path(tmp), n)
        assert _read(log) == _read(bag) == n
        log_s = best_time_s(lambda: _read(log))
        bag_s = best_time_s(lambda: _read(bag))
    return [Row("carmen", f"scans per s, {n} FLASER lines opened and decoded", n / log_s, "scans/s",
                "the same scans in a ROS 1 bag", n / bag_s, True, ">= 1/4 of the ROS 1 bag")]
