"""Fleet mode (``bagtools batch``): throughput on 2 workers against the same bags one after another in one process.

16 simulated 60 s bags without depth clouds (``--quick``: 4 bags of 20 s),
``ndt-odom`` on each. Both sides are timed end to end as a user sees them,
each as a fresh process: ``bagtools batch ndt-odom BAGS --out DIR --workers 2``
(Python, Dask, the embedded LocalCluster, the bags, fleet.csv/.parquet/.png,
the cluster's shutdown) against a Python loop over the same library calls the
single command makes (``NdtOdomPipeline(bag).run()`` then
``write_ndt_odom``), in one process. The sides alternate and the best of each
is kept, so a burst of load from elsewhere does not decide the ratio.

Second row: a rerun of the finished batch (every bag skipped from its marker,
no cluster started) against the batch's own first run.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from bench.common import Row
from simulate.pipeline import SimConfig, simulate_bag

REPO = Path(__file__).resolve().parents[1]

_SEQUENTIAL = """
import sys
from pathlib import Path
from bagtools.ndtodom import NdtOdomOptions, NdtOdomPipeline, write_ndt_odom
out = Path(sys.argv[1])
for bag in sys.argv[2:]:
    result = NdtOdomPipeline(bag, NdtOdomOptions()).run()
    write_ndt_odom(result, out / Path(bag).name)
"""


def _timed(argv: list[str]) -> float:
    """Wall-clock seconds of a fresh process running ``argv`` (which must succeed)."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")])}
    t0 = time.perf_counter()
    done = subprocess.run(argv, env=env, cwd=REPO, capture_output=True, text=True)
    elapsed = time.perf_counter() - t0
    if done.returncode != 0:
        raise RuntimeError(f"{' '.join(argv[:5])} ... failed ({done.returncode}): {done.stderr[-2000:]}")
    return elapsed


def run(quick: bool) -> list[Row]:
    """2-worker batch vs sequential bags/s on simulated 60 s bags; a finished batch's rerun vs its first run."""
    n_bags, duration_s, repeat = (4, 20.0, 1) if quick else (16, 60.0, 2)
    with tempfile.TemporaryDirectory(prefix="bench_batch_") as tmp:
        root = Path(tmp)
        bags = [str(simulate_bag(root / "bags" / f"robot{i:02d}",
                                 SimConfig(duration_s=duration_s, seed=i, cloud=False)).path) for i in range(n_bags)]
        sequential_s, batch_s = float("inf"), float("inf")
        for attempt in range(repeat):
            seq_out, batch_out = root / f"seq{attempt}", root / f"batch{attempt}"
            sequential_s = min(sequential_s, _timed([sys.executable, "-c", _SEQUENTIAL, str(seq_out), *bags]))
            batch_s = min(batch_s, _timed([sys.executable, "-m", "bagtools", "batch", "ndt-odom", *bags,
                                           "--out", str(batch_out), "--workers", "2"]))
            shutil.rmtree(seq_out)
        rerun_s = _timed([sys.executable, "-m", "bagtools", "batch", "ndt-odom", *bags, "--out", str(batch_out)])
    what = f"{n_bags} simulated {duration_s:g} s bags (no clouds), ndt-odom"
    return [
        Row("batch", f"{what}, 2 workers (embedded LocalCluster), end to end", n_bags / batch_s, "bags/s",
            "same bags one after another in one process (library calls)", n_bags / sequential_s, True, ">= 1.8x"),
        Row("batch", f"rerun of the finished batch ({what}): every bag skipped", rerun_s, "s",
            "the batch's first run", batch_s, False, "<= 0.1x"),
    ]
