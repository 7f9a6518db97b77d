"""Global localization (``bagtools.localize``): one scan placed in a whole map, any heading, no initial pose.

The map: the CSAIL building (``../shared/data/real/csail_scans``, skipped when
absent) mapped at 5 cm from its reference poses with returns up to 20 m (as
``slam`` maps), and four marks at the corners of a 100 m x 100 m square around
it, so that the search spans the issue's 100 m x 100 m. Twenty scans along the
path, each searched alone:

- seconds per scan (median), the whole search (coarse branch and bound with the
  distinct places, then each refined at 5 cm). Baseline in the same run: the
  branch and bound for the single best place over the same window (what the
  hypotheses cost on top). Target <= 2 s;
- the share of scans whose best hypothesis is the place (30 cm, 3 degrees of
  the reference), and the share where the place is among the hypotheses.
"""

from __future__ import annotations

import math
import tempfile
import time
from pathlib import Path

import numpy as np

from bench.common import Row

REAL_DIR = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "real"
SIDE_M = 100.0


def run(quick: bool) -> list[Row]:
    from bagtools.grid import read_nav2_map, write_nav2_map
    from bagtools.gridmap import GridMapOptions, GridMapPipeline
    from bagtools.io import open_bag
    from bagtools.localize import GlobalLocalizer
    from bagtools.localize.global_search import REACH_M
    from bagtools.ndt import match_scans_grid, voxel_subsample
    from bagtools.ndtodom import run_front_end
    from bagtools.simtruth import read_ground_truth
    from bagtools.transforms import tform2pose

    bag = REAL_DIR / "csail_scans"
    if not bag.is_dir():
        return []
    options = GridMapOptions(poses="ground-truth", frame="map", resolution=20.0, max_range_m=20.0)
    grid = GridMapPipeline(bag, options).run().grid
    with tempfile.TemporaryDirectory(prefix="bench_localize_") as tmp:
        points = read_nav2_map(write_nav2_map(grid, Path(tmp) / "map")).occupied_points()
    centre = 0.5 * (points.min(axis=0) + points.max(axis=0))
    corners = centre + 0.5 * SIDE_M * np.array([[-1, -1], [-1, 1], [1, -1], [1, 1]])
    marks = np.concatenate([c + np.c_[np.arange(-0.5, 0.5, 0.05), np.zeros(20)] for c in corners])
    localizer = GlobalLocalizer(np.r_[points, marks])
    front = run_front_end(bag)
    with open_bag(bag) as reader:
        stamps, T_map_base, _ = read_ground_truth(reader)
    truth = tform2pose(T_map_base[np.searchsorted(stamps, front.front_end.stamps_ns())])
    picks = range(5, 400, 80 if quick else 20)
    search_s, best_s, best_right, among = [], [], 0, 0
    window = (float(localizer.half_extent[0]), float(localizer.half_extent[1]), math.pi)
    for k in picks:
        scan = front.front_end.steps[k].points_base
        t0 = time.perf_counter()
        hyps = localizer.search(scan)
        search_s.append(time.perf_counter() - t0)
        right = [np.hypot(*(h.pose[:2] - truth[k, :2])) < 0.3
                 and abs((h.pose[2] - truth[k, 2] + math.pi) % (2 * math.pi) - math.pi) < math.radians(3.0)
                 for h in hyps]
        best_right += bool(right and right[0])
        among += any(right)
        t0 = time.perf_counter()
        match_scans_grid(voxel_subsample(scan, localizer.coarse.resolution_m), localizer.coarse,
                         initial_pose=(localizer.centre[0], localizer.centre[1], 0.0), search_range=window,
                         angular_resolution_rad=localizer.coarse.resolution_m / REACH_M, min_score=0.3)
        best_s.append(time.perf_counter() - t0)
    n = len(picks)
    span = 2 * localizer.half_extent
    label = f"{span[0]:.0f} m x {span[1]:.0f} m map at 5 cm (CSAIL + corner marks), {n} scans"
    return [
        Row("global localization", f"seconds per scan, median, {label}", float(np.median(search_s)), "s",
            "best place only, same window", float(np.median(best_s)), False, "<= 2 s"),
        Row("global localization", f"scans whose best hypothesis is the place, {label}", best_right / n, "share",
            "scans whose hypotheses hold the place", among / n, True, "all held"),
    ]
