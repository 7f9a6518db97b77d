"""map-cloud throughput: input points per second end to end (read, decode, tf lookup, sample,
transform, accumulate) against the bare read-and-decode of the same clouds; and the cost of results.mcap:
the run with its files written, with results.mcap against without."""

from __future__ import annotations

import tempfile
from pathlib import Path

from bagtools.cloudmap import CloudMapOptions, CloudMapPipeline, write_cloud_map
from bagtools.dataset import SensorStream
from bagtools.io import open_bag
from bench.common import Row, best_time_s
from bagtools_simulate.pipeline import SimConfig, simulate_bag

TOPIC = "/camera/depth/points"


def _read_decode(bag: Path) -> int:
    """The clouds read and decoded as every command reads them (the dataset stream), nothing else."""
    with open_bag(bag) as reader:
        return sum(item.points.shape[0] for item in SensorStream(reader, TOPIC, desc=None))


def run(quick: bool) -> list[Row]:
    rows = []
    cases = [((160, 120), 30.0 if quick else 60.0), ((640, 480), 5.0 if quick else 15.0)]
    with tempfile.TemporaryDirectory() as tmp:
        for (w, h), duration in cases:
            bag = Path(tmp) / f"sim_{w}x{h}"
            simulate_bag(bag, SimConfig(duration_s=duration, cloud_size=(w, h)))
            n_points = _read_decode(bag)
            t_base = best_time_s(lambda: _read_decode(bag), repeat=2)
            t_map = best_time_s(lambda: CloudMapPipeline(bag, CloudMapOptions()).run(), repeat=2)
            rows.append(Row("map-cloud", f"input points/s end to end, {w}x{h} clouds, --sample 0.01",
                            n_points / t_map, "points/s", "read+decode only", n_points / t_base, True,
                            ">= 0.8x, one pass"))
            out = Path(tmp) / f"out_{w}"

            def with_files(mcap: bool) -> None:
                result = CloudMapPipeline(bag, CloudMapOptions(), keep_inputs=mcap).run()
                write_cloud_map(result, out, force=True, mcap=mcap)

            t_plain = best_time_s(lambda: with_files(False), repeat=2)
            t_mcap = best_time_s(lambda: with_files(True), repeat=2)
            rows.append(Row("map-cloud", f"input points/s with files, {w}x{h} clouds, with results.mcap",
                            n_points / t_mcap, "points/s", "same run with --no-mcap", n_points / t_plain))
    return rows
