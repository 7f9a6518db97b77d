"""Bag-reading throughput: read + decode PointCloud2 and LaserScan to numpy, against
rosbags' plain read of the raw bytes of the same messages (the ratio is the decoding cost).

"Read + decode" is what every command does: open the bag and iterate the topic through
:mod:`bagtools.dataset.scans` (``ScanStream`` for scans, ``SensorStream`` for clouds), which
decode straight from the CDR bytes (:mod:`bagtools.io.cdr`). The rows of the rosbags
message path (deserialize, then decode) are kept for comparison.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from bagtools.dataset.scans import ScanStream, SensorStream
from bagtools.io import decode_laserscan, decode_pointcloud2, open_bag
from bench.common import Row, best_time_s

TYPESTORE = get_typestore(Stores.ROS2_HUMBLE)


def _header(T, stamp_ns: int, frame: str):
    return T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9), frame_id=frame)


def write_bench_bag(path: Path, n_clouds: int, width: int, height: int, n_scans: int) -> Path:
    """A rosbag2 MCAP (zstd) with depth-camera-like clouds (x y z pad, 16 B/point, ~10% NaN) and 360-beam scans."""
    T = TYPESTORE.types
    rng = np.random.default_rng(0)
    writer = Writer(path, version=9, storage_plugin=StoragePlugin.MCAP)
    writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
    fields = [T["sensor_msgs/msg/PointField"](name=n, offset=4 * i, datatype=7, count=1) for i, n in enumerate("xyz")]
    with writer:
        c_cloud = writer.add_connection("/camera/depth/points", "sensor_msgs/msg/PointCloud2", typestore=TYPESTORE)
        c_scan = writer.add_connection("/scan", "sensor_msgs/msg/LaserScan", typestore=TYPESTORE)
        for i in range(n_clouds):
            pts = np.zeros((height * width, 4), dtype=np.float32)
            pts[:, :3] = rng.uniform(-3, 3, size=(height * width, 3))
            pts[rng.random(height * width) < 0.1, :3] = np.nan
            msg = T["sensor_msgs/msg/PointCloud2"](
                header=_header(T, i * 500_000_000, "camera_rgb_optical_frame"), height=height, width=width, fields=fields,
                is_bigendian=False, point_step=16, row_step=16 * width, data=pts.view(np.uint8).reshape(-1), is_dense=False)
            writer.write(c_cloud, i * 500_000_000, TYPESTORE.serialize_cdr(msg, "sensor_msgs/msg/PointCloud2"))
        for i in range(n_scans):
            ranges = rng.uniform(0.12, 3.5, 360).astype(np.float32)
            msg = T["sensor_msgs/msg/LaserScan"](
                header=_header(T, i * 200_000_000, "base_scan"), angle_min=0.0, angle_max=2 * np.pi * 359 / 360,
                angle_increment=2 * np.pi / 360, time_increment=0.0, scan_time=0.2, range_min=0.12, range_max=3.5,
                ranges=ranges, intensities=np.zeros(0, dtype=np.float32))
            writer.write(c_scan, i * 200_000_000 + 1, TYPESTORE.serialize_cdr(msg, "sensor_msgs/msg/LaserScan"))
    return path


def _raw_read(path: Path, topic: str) -> int:
    nbytes = 0
    with AnyReader([path]) as reader:
        conns = [c for c in reader.connections if c.topic == topic]
        for _, _, raw in reader.messages(connections=conns):
            nbytes += len(raw)
    return nbytes


def _decode_read(path: Path, topic: str, decode) -> int:
    """The rosbags message path: every message deserialized, then decoded."""
    n = 0
    with open_bag(path) as bag:
        for rec in bag.messages([topic]):
            n += decode(rec.msg).stamp_ns >= 0
    return n


def _stream_read(path: Path, topic: str, stream) -> int:
    """What the commands do: the topic through its dataset stream."""
    with open_bag(path) as bag:
        return sum(1 for _ in stream(bag, topic, desc=None))


def run(quick: bool) -> list[Row]:
    rows: list[Row] = []
    n_clouds, n_scans = (40, 500) if quick else (200, 3000)
    with tempfile.TemporaryDirectory() as tmp:
        bag = write_bench_bag(Path(tmp) / "bench", n_clouds, 160, 120, n_scans)
        for topic, decode, stream, count, name, target in (
            ("/camera/depth/points", decode_pointcloud2, SensorStream, n_clouds, "PointCloud2 160x120", ">= 0.9x"),
            ("/scan", decode_laserscan, ScanStream, n_scans, "LaserScan 360", ">= 0.8x"),
        ):
            nbytes = _raw_read(bag, topic)
            t_raw = best_time_s(lambda: _raw_read(bag, topic))
            t_dec = best_time_s(lambda: _stream_read(bag, topic, stream))
            t_msg = best_time_s(lambda: _decode_read(bag, topic, decode))
            base = "rosbags raw read"
            rows.append(Row("io", f"read+decode {name}", nbytes / t_dec / 1e6, "MB/s", base, nbytes / t_raw / 1e6,
                            True, target))
            rows.append(Row("io", f"read+decode {name}", count / t_dec, "msg/s", base, count / t_raw, True, target))
            rows.append(Row("io", f"read, deserialize (rosbags), decode {name}", count / t_msg, "msg/s", base,
                            count / t_raw))
    rows += _startup_rows()
    return rows


def _cpu_s(argv: list[str]) -> float:
    """User + system CPU seconds of one run of ``argv`` (best of three)."""
    best = float("inf")
    for _ in range(3):
        proc = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        _, _, usage = os.wait4(proc.pid, 0)
        best = min(best, usage.ru_utime + usage.ru_stime)
    return best


def _startup_rows() -> list[Row]:
    """`bagtools info` on the smallest real bag (tf_example.bag), CPU seconds, against `python -c pass` (#44)."""
    bag = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "real" / "tf_example.bag"
    if not bag.exists():
        return []
    info = _cpu_s([sys.executable, "-m", "bagtools", "info", str(bag)])
    bare = _cpu_s([sys.executable, "-c", "pass"])
    return [Row("start-up", "bagtools info tf_example.bag, CPU s (user + sys)", info, "s", "python -c pass", bare,
                False, "<= 0.3 CPU s on the reference machine (scale by the calibration)")]
