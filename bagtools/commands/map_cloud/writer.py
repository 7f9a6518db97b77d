"""Writing a cloud map's files together, atomically."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from bagtools.commands.map_cloud.files import write_point_cloud
from bagtools.commands.map_cloud.pipeline import CloudMapResult
from bagtools.commands.map_cloud.render import render_map_png
from bagtools.outputs import OutputDir
from bagtools.results import RESULTS_MCAP, ResultsBag, run_outputs
from bagtools.trajectory.tum import tum_text

CLOUD_MAP_FILES = ["cloud_map.pcd", "cloud_map.ply", "cloud_map.png", "trajectory.tum", "summary.json", RESULTS_MCAP]


def cloud_map_outputs(mcap: bool, refine: bool) -> list[str]:
    """The files a map-cloud run writes: trajectory.tum only when it refines, results.mcap only with ``mcap``, so
    that ``--force`` replaces (and removes as stale) only what the run itself writes."""
    return [n for n in run_outputs(CLOUD_MAP_FILES, mcap) if refine or n != "trajectory.tum"]


def write_cloud_map(result: CloudMapResult, out_dir: str | Path, force: bool = False, mcap: bool = True) -> list[Path]:
    """Write cloud_map.pcd/.ply/.png, summary.json, trajectory.tum (the refined poses, with --refine) and (with
    ``mcap``) results.mcap into ``out_dir``; all or nothing.

    results.mcap needs the pipeline's placed inputs (``CloudMapPipeline(..., keep_inputs=True)``).
    """
    frame = result.summary.get("frame", "map")
    written = ["cloud_map.pcd", "cloud_map.ply", "cloud_map.png", "summary.json"]
    with OutputDir(out_dir, cloud_map_outputs(mcap, result.trajectory is not None), force) as staged:
        write_point_cloud(staged / "cloud_map.pcd", result.cloud, frame)
        write_point_cloud(staged / "cloud_map.ply", result.cloud, frame)
        render_map_png(staged / "cloud_map.png", result.points, frame, result.sensor_path,
                       title=f"{result.summary.get('topic', '')} in {frame}")
        if result.trajectory is not None:
            (staged / "trajectory.tum").write_text(tum_text(result.trajectory, frame, result.trajectory_body))
            written.append("trajectory.tum")
        (staged / "summary.json").write_text(json.dumps(result.summary, indent=2))
        if mcap:
            with ResultsBag(staged / RESULTS_MCAP, namespace="map_cloud") as bag:
                write_cloud_map_results(bag, result)
            written.append(RESULTS_MCAP)
    return [Path(out_dir) / name for name in written]


def write_cloud_map_results(bag: ResultsBag, result: CloudMapResult) -> None:
    """The map as /cloud_map in its frame; each placed message again on its topic at its stamp, in its sensor
    frame (the points that went into the map, or the LaserScan); /tf (map frame -> robot base at each message)
    and /tf_static (base -> sensor) so they land where the map put them; the base's path as /trajectory."""
    frame = result.summary.get("frame", "map")
    topic = result.summary.get("topic", "/points")
    cloud = result.cloud
    bag.point_cloud("/cloud_map", cloud.points, frame, cloud.intensity, cloud.rgb)
    inputs = result.inputs
    if not inputs:
        return
    stamps = np.array([p.stamp_ns for p in inputs], dtype=np.int64)
    T_frame_sensor = np.stack([p.T_frame_sensor for p in inputs])
    bases = {p.base_frame for p in inputs}
    if len(bases) == 1 and None not in bases:
        (base,) = bases
        sensors = {p.frame_id: p.T_base_sensor for p in reversed(inputs)}  # the first one of each frame
        T_frame_base = T_frame_sensor @ np.linalg.inv(np.stack([p.T_base_sensor for p in inputs]))
        bag.robot(frame, base, stamps, T_frame_base, sensors)
        bag.path("/trajectory", stamps, T_frame_base, frame)
    else:  # tf does not tie the sensor to a base: each sensor frame moves in the map's frame
        for sensor in dict.fromkeys(p.frame_id for p in inputs):
            rows = np.array([p.frame_id == sensor for p in inputs])
            bag.tf(frame, sensor, stamps[rows], T_frame_sensor[rows])
        bag.path("/trajectory", stamps, T_frame_sensor, frame)
    if all(p.scan is not None for p in inputs):
        bag.scans(topic, [p.scan for p in inputs])
    else:
        bag.clouds(topic, [(p.stamp_ns, p.frame_id, p.points, p.intensity, p.rgb) for p in inputs])
