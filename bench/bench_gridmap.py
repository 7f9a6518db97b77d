"""``bagtools grid`` throughput: scans per second end to end (read, decode, tf lookup, ray casting into
the grid, scoring against the true world, writing map.pgm/.yaml/.png/summary.json) against the bare
read-and-decode of the same scans, on a simulated lap (360 beams, 3.5 m, 5 cm cells); and the cost of
results.mcap (/map, /trajectory, /tf and every scan re-published) against the same run with --no-mcap."""

from __future__ import annotations

import tempfile
from pathlib import Path

from bagtools.gridmap import GridMapOptions, GridMapPipeline, write_grid_map
from bagtools.io import decode_laserscan, open_bag
from bench.common import Row, best_time_s
from bagtools_simulate.pipeline import SimConfig, simulate_bag

TOPIC = "/scan"


def _read_decode(bag: Path) -> int:
    n = 0
    with open_bag(bag) as reader:
        for rec in reader.messages([TOPIC]):
            n += decode_laserscan(rec.msg).ranges_m.size > 0
    return n


def _grid(bag: Path, out_dir: Path, options: GridMapOptions, write: bool, mcap: bool = False) -> None:
    result = GridMapPipeline(bag, options, keep_scans=mcap).run()
    if write:
        write_grid_map(result, out_dir, force=True, mcap=mcap)


def run(quick: bool) -> list[Row]:
    duration = 60.0 if quick else 300.0
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        bag = Path(tmp) / "lap"
        simulate_bag(bag, SimConfig(duration_s=duration, route="lap", cloud=False))
        n_scans = _read_decode(bag)
        t_base = best_time_s(lambda: _read_decode(bag), repeat=2)
        cases = [("tf poses in map, with scoring and outputs", GridMapOptions(), True),
                 ("ground-truth poses, with scoring and outputs", GridMapOptions(poses="ground-truth"), True)]
        for label, options, write in cases:
            t = best_time_s(lambda: _grid(bag, Path(tmp) / "out", options, write), repeat=2)
            rows.append(Row("grid", f"scans/s end to end, {duration:g} s lap, {label}", n_scans / t, "scans/s",
                            "read+decode only", n_scans / t_base))
        t_plain = best_time_s(lambda: _grid(bag, Path(tmp) / "out", GridMapOptions(), True, False), repeat=2)
        t_mcap = best_time_s(lambda: _grid(bag, Path(tmp) / "out", GridMapOptions(), True, True), repeat=2)
        rows.append(Row("grid", f"scans/s end to end, {duration:g} s lap, tf poses, with results.mcap", n_scans / t_mcap,
                        "scans/s", "same run with --no-mcap", n_scans / t_plain))
    return rows
