"""``bagtools grid`` throughput: scans per second end to end (read, decode, tf lookup, ray casting into
the grid, scoring against the true world, writing map.pgm/.yaml/.png/summary.json) against the bare
read-and-decode of the same scans, on a simulated lap (360 beams, 3.5 m, 5 cm cells); and the cost of
results.mcap (/map, /trajectory, /tf and every scan re-published) against the same run with --no-mcap; and the
memory a large map's pictures take (a 250 m x 200 m campus at 5 cm: 20 million cells) against its probability
matrix alone, each in its own child process."""

from __future__ import annotations

import subprocess
import sys
import tempfile
from pathlib import Path

from bagtools.commands.grid import GridMapOptions, GridMapPipeline, write_grid_map
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


_LARGE_MAP = """
import resource, sys, numpy as np
from bagtools.grid import OccupancyGrid, render_map_png
from bagtools.grid.render import render_slam_map_png
grid = OccupancyGrid(250.0, 200.0, 20.0)
grid.insert_ray(np.array([5.0, 5.0, 0.0]), np.array([240.0]), np.array([0.7]), max_range=300.0)
path = np.array([[10.0, 10.0], [200.0, 150.0]])
before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
if sys.argv[1] == "probability":
    grid.occupancy_matrix("probability")
elif sys.argv[1] == "slam":
    render_slam_map_png(grid, path, np.zeros((0, 2, 2)))
else:
    render_map_png(grid, path)
print((resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before) / 1024.0)
"""


def _large_map_mb(what: str) -> float:
    out = subprocess.run([sys.executable, "-c", _LARGE_MAP, what], capture_output=True, text=True, check=True)
    return float(out.stdout.strip())


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
    matrix_mb = _large_map_mb("probability")
    for what, name in (("slam", "slam map.png"), ("grid", "grid map.png")):
        rows.append(Row("grid", f"peak memory drawing {name} of a 20 M-cell map (250 x 200 m at 5 cm)",
                        _large_map_mb(what), "MB", "its float64 probability matrix", matrix_mb,
                        higher_is_better=False, target="<= 3x the matrix (before: 1.56 GB, 18x)"))
    return rows
