"""map-cloud throughput: input points per second end to end (read, decode, tf lookup, sample,
transform, accumulate) against the bare read-and-decode of the same clouds; and the cost of results.mcap:
the run with its files written, with results.mcap against without; and map-cloud --refine (Open3D ICP) on laps
whose odometry drifts: the map's distance to the true surfaces against the plain map and the map from true poses."""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from bagtools.commands.map_cloud import CloudMapOptions, CloudMapPipeline, write_cloud_map
from bagtools.dataset import SensorStream
from bagtools.io import open_bag
from bagtools.simtruth import load_sim_world, read_ground_truth
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
        rows += _refine_rows(Path(tmp), quick)
    return rows


def _true_pose_distances(bag: Path, result) -> np.ndarray:
    """Distances to the true surfaces of the clouds ``result`` placed (keep_inputs), placed instead at the
    ground-truth pose of the base at their stamps (positions interpolated): the map a perfect odometry gives."""
    with open_bag(bag) as reader:
        world = load_sim_world(reader)
        stamps, T_map_base, _ = read_ground_truth(reader)
    placed = []
    for item in result.inputs:
        k = int(np.clip(np.searchsorted(stamps, item.stamp_ns), 1, len(stamps) - 1))
        a = (item.stamp_ns - stamps[k - 1]) / (stamps[k] - stamps[k - 1])
        T = T_map_base[k - 1].copy()
        T[:3, 3] = (1 - a) * T_map_base[k - 1][:3, 3] + a * T_map_base[k][:3, 3]
        T = T @ item.T_base_sensor
        placed.append(item.points.astype(np.float64) @ T[:3, :3].T + T[:3, 3])
    return world.surface_distance_m(np.vstack(placed))


def _refine_rows(tmp: Path, quick: bool) -> list[Row]:
    """map-cloud --refine in odom on laps with drifting odometry: the map's distance to the true surfaces against
    the plain map-cloud (same 0.1 sample) and the map from the true poses; its time against the plain run."""
    rows = []
    for noise in ("realistic", "high"):
        bag = tmp / f"sim_refine_{noise}"
        simulate_bag(bag, SimConfig(duration_s=60.0 if quick else 180.0, odom_noise=noise))
        plain_options = CloudMapOptions(frame="odom", sample=0.1)
        plain = CloudMapPipeline(bag, plain_options, keep_inputs=True).run()
        refined = CloudMapPipeline(bag, CloudMapOptions(frame="odom", refine=True)).run()
        truth = _true_pose_distances(bag, plain)
        before, after = plain.summary["accuracy_vs_truth_m"], refined.summary["accuracy_vs_truth_m"]
        cap = f"map-cloud --refine, frame odom, {noise} odometry noise, {60 if quick else 180} s lap"
        for stat in ("median", "p95"):
            value = float(np.median(truth)) if stat == "median" else float(np.percentile(truth, 95))
            rows.append(Row(cap, f"{stat} distance of the map to the true surfaces", after[stat], "m",
                            "plain map-cloud (same sample)", before[stat], False,
                            f"<= 1.5x the map from true poses ({value:.4f} m)"))
        t_plain = best_time_s(lambda: CloudMapPipeline(bag, plain_options).run(), repeat=1)
        t_refine = best_time_s(lambda: CloudMapPipeline(bag, CloudMapOptions(frame="odom", refine=True)).run(),
                               repeat=1)
        rows.append(Row(cap, "time", t_refine, "s", "plain map-cloud (same sample)", t_plain, False, ""))
    return rows
