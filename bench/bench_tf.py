"""tf buffer speed: batched lookups over a 3-edge chain, and building the buffer from a 10-minute bag."""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from bench.common import Row, best_time_s

S = 1_000_000_000


def _unit_quats(rng: np.random.Generator, n: int) -> np.ndarray:
    q = rng.normal(size=(n, 4))
    return q / np.linalg.norm(q, axis=1)[:, None]


def _chain_buffer(duration_s: int):
    """map->odom (10 Hz), odom->base_link (30 Hz), base_link->laser (static): 3 edges."""
    from bagtools.tf import TfBuffer

    rng = np.random.default_rng(1)
    buf = TfBuffer()
    for parent, child, hz in [("map", "odom", 10), ("odom", "base_link", 30)]:
        n = duration_s * hz + 1
        buf.set_transform(parent, child, np.arange(n, dtype=np.int64) * (S // hz), rng.normal(size=(n, 3)),
                          _unit_quats(rng, n))
    buf.set_transform("base_link", "laser", 0, (0.1, 0.0, 0.2), (0.0, 0.0, 0.0, 1.0), static=True)
    return buf


def _lookup_rows(quick: bool) -> list[Row]:
    duration_s = 600
    n = 100_000 if quick else 1_000_000
    buf = _chain_buffer(duration_s)
    stamps = np.sort(np.random.default_rng(2).integers(0, duration_s * S, n))
    batch_s = best_time_s(lambda: buf.lookup("map", "laser", stamps), repeat=3)
    loop_n = 2_000 if quick else 5_000
    loop_s = best_time_s(lambda: [buf.lookup("map", "laser", int(s)) for s in stamps[:loop_n]], repeat=1)
    array_s = best_time_s(lambda: [buf.lookup("map", "laser", stamps[k:k + 1]) for k in range(loop_n)], repeat=1)
    return [Row("tf lookup", f"batched lookups/s, 3-edge chain, {n:.0e} stamps", n / batch_s, "lookups/s",
                "same buffer, one stamp per call", loop_n / loop_s, True, ">= 1e6 lookups/s on one core"),
            Row("tf lookup", "one stamp per call (int stamp: the one-stamp path), 3-edge chain", loop_n / loop_s,
                "lookups/s", "one-element array per call (the batched path)", loop_n / array_s, True,
                ">= 60k lookups/s (0.5x tf2's lookup_transform_core from Python, issue #25)")]


def _write_bag(path: Path, duration_s: int) -> Path:
    """A rosbag2 MCAP of ``duration_s`` seconds: /tf at 30 Hz (odom->base_footprint) + 10 Hz (map->odom), /tf_static."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    T = store.types

    def tf_msg(stamp_ns: int, parent: str, child: str, x: float, yaw: float):
        header = T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=stamp_ns // S, nanosec=stamp_ns % S),
                                          frame_id=parent)
        transform = T["geometry_msgs/msg/Transform"](
            translation=T["geometry_msgs/msg/Vector3"](x=x, y=0.0, z=0.0),
            rotation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=float(np.sin(yaw / 2)), w=float(np.cos(yaw / 2))))
        return T["tf2_msgs/msg/TFMessage"](transforms=[T["geometry_msgs/msg/TransformStamped"](
            header=header, child_frame_id=child, transform=transform)])

    msgtype = "tf2_msgs/msg/TFMessage"
    t0 = 1_700_000_000 * S
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        tf = writer.add_connection("/tf", msgtype, typestore=store)
        static = writer.add_connection("/tf_static", msgtype, typestore=store)
        writer.write(static, t0, store.serialize_cdr(tf_msg(t0, "base_footprint", "base_scan", -0.064, 0.0), msgtype))
        for i in range(duration_s * 30):
            t = t0 + i * S // 30
            writer.write(tf, t, store.serialize_cdr(tf_msg(t, "odom", "base_footprint", 0.01 * i, 0.001 * i), msgtype))
            if i % 3 == 0:
                writer.write(tf, t, store.serialize_cdr(tf_msg(t, "map", "odom", 0.001 * i, 0.0), msgtype))
    return path


def _construction_rows(quick: bool) -> list[Row]:
    from bagtools.io import open_bag, read_tf_arrays
    from bagtools.tf import TfBuffer

    duration_s = 60 if quick else 600
    with tempfile.TemporaryDirectory() as tmp:
        bag = _write_bag(Path(tmp) / "tf_bag", duration_s)

        def read_only() -> None:
            with open_bag(bag) as reader:
                read_tf_arrays(reader)

        def build() -> None:
            buf = TfBuffer.from_bag(bag)
            buf.lookup("map", "base_scan", np.array([1_700_000_000 * S + S]))   # forces the sorted tracks

        read_s = best_time_s(read_only, repeat=1 if not quick else 2)
        build_s = best_time_s(build, repeat=1 if not quick else 2)
    return [Row("tf buffer", f"TfBuffer.from_bag, {duration_s // 60}-minute bag (40 tf msgs/s)", build_s, "s",
                "reading + decoding /tf alone", read_s, False, "close to the read time")]


def run(quick: bool) -> list[Row]:
    return _lookup_rows(quick) + _construction_rows(quick)
