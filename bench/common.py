"""Shared pieces of the benchmark runner: the row type, a timer, a log cut in halves."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path


@dataclass(frozen=True)
class Row:
    """One benchmark figure and its same-run baseline.

    ``ratio`` is value / baseline_value: for throughputs (higher is better) a
    ratio above 1 means bagtools beats the baseline; ``higher_is_better`` says
    how to read it.
    """

    capability: str
    measure: str
    value: float
    unit: str
    baseline: str
    baseline_value: float
    higher_is_better: bool = True
    target: str = ""

    @property
    def ratio(self) -> float:
        return self.value / self.baseline_value if self.baseline_value else float("nan")


def best_time_s(fn: Callable[[], object], repeat: int = 3) -> float:
    """Best wall-clock seconds of ``repeat`` calls of ``fn`` (the least-disturbed run)."""
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def bag_halves(bag: Path, out_dir: Path, topic: str = "/scan") -> tuple[Path, Path]:
    """A ROS 1 bag cut in two by its scans, in one pass: the first half with everything recorded before its last
    scan, the second with everything from its first scan on (and /tf_static)."""
    from rosbags.rosbag1 import Reader, Writer

    paths = (out_dir / f"{bag.stem}_first.bag", out_dir / f"{bag.stem}_second.bag")
    with Reader(bag) as reader, Writer(paths[0]) as first, Writer(paths[1]) as second:
        half = sum(c.msgcount for c in reader.connections if c.topic == topic) // 2
        out = [{c.id: w.add_connection(c.topic, c.msgtype, msgdef=c.msgdef.data, md5sum=c.digest)
                for c in reader.connections} for w in (first, second)]
        scans = 0
        for connection, stamp_ns, raw in reader.messages():
            if connection.topic == topic:
                scans += 1
                into_first, into_second = scans <= half, scans > half
            else:
                into_first, into_second = scans <= half, scans >= half or connection.topic == "/tf_static"
            if into_first:
                first.write(out[0][connection.id], stamp_ns, raw)
            if into_second:
                second.write(out[1][connection.id], stamp_ns, raw)
    return paths
