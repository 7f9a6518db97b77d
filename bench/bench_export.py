"""``bagtools export`` throughput: rows per second into each format, against the bare read + decode of the
same messages (what any consumer of the topic pays at least), on a simulated bag."""

from __future__ import annotations

import tempfile
from pathlib import Path

from bagtools.commands.export import export_topic
from bagtools.commands.export.tables import DECODERS
from bagtools.io import open_bag
from bench.common import Row, best_time_s
from bagtools_simulate.pipeline import SimConfig, simulate_bag


def _read_decode(bag: Path, topic: str) -> int:
    n = 0
    with open_bag(bag) as reader:
        decode = DECODERS.get(reader.topics[topic].msgtype, lambda msg: msg)  # other types: deserializing is all
        for rec in reader.messages([topic]):
            decode(rec.msg)
            n += 1
    return n


def run(quick: bool) -> list[Row]:
    duration = 20.0 if quick else 120.0
    rows = []
    with tempfile.TemporaryDirectory(prefix="bench_export_") as tmp:
        bag = Path(tmp) / "sim"
        simulate_bag(bag, SimConfig(duration_s=duration, cloud_size=(160, 120), cloud_rate_hz=2.0))
        cases = [("/odom", "csv"), ("/odom", "parquet"), ("/scan", "csv"), ("/scan", "parquet"), ("/scan", "npz"),
                 ("/tf", "parquet"), ("/camera/depth/points", "parquet"), ("/camera/depth/points", "csv"),
                 ("/imu", "parquet"), ("/joint_states", "csv")]  # flattened from their definitions
        for topic, fmt in cases:
            out = Path(tmp) / f"out.{fmt}"
            summary = export_topic(bag, topic, out, force=True)
            t_base = best_time_s(lambda: _read_decode(bag, topic), repeat=2)
            t_export = best_time_s(lambda: export_topic(bag, topic, out, force=True), repeat=2)
            rows.append(Row("export", f"{topic} ({summary.messages} msgs) to .{fmt}", summary.rows / t_export, "rows/s",
                            "read + decode of the same messages", summary.rows / t_base))
    return rows
