"""Writing a laser-odometry run's files together, atomically."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from bagtools.odometry.pipeline import NdtOdomResult
from bagtools.commands.ndt_odom.plots import render_scan_map_png, render_trajectories_png
from bagtools.outputs import OutputDir
from bagtools.results import RESULTS_MCAP, ResultsBag, run_outputs
from bagtools.trajectory import tum_text

#: Every file the command may write (any existing one is refused without --force).
NDT_ODOM_FILES = ["trajectory.tum", "odometry.tum", "ground_truth.tum", "trajectory.png", "scan_map.png", "summary.json",
                  RESULTS_MCAP]
#: Edge of the voxels that thin the scan map of results.mcap, metres.
CLOUD_MAP_VOXEL_M = 0.05


def write_ndt_odom(result: NdtOdomResult, out_dir: str | Path, force: bool = False, mcap: bool = True) -> list[Path]:
    """Write what the run computed into ``out_dir``, all or nothing; returns the paths written.

    trajectory.tum, trajectory.png, scan_map.png and (with ``mcap``) results.mcap
    need at least one scan; odometry.tum and ground_truth.tum are written when
    the bag had them; summary.json always.
    """
    frame = result.summary.get("odometry_frame", "odom")
    body = result.summary.get("base_frame")
    written: list[str] = []
    with OutputDir(out_dir, run_outputs(NDT_ODOM_FILES, mcap), force) as staged:
        if result.trajectory is not None:
            for name, traj in (("trajectory.tum", result.trajectory), ("odometry.tum", result.odometry),
                               ("ground_truth.tum", result.ground_truth)):
                if traj is not None:
                    (staged / name).write_text(tum_text(traj, frame, body))
                    written.append(name)
            render_trajectories_png(staged / "trajectory.png", frame, result.trajectory, result.odometry,
                                    result.ground_truth, title=f"{result.summary.get('topic', '')}: NDT laser odometry")
            render_scan_map_png(staged / "scan_map.png", frame, result.scan_points, result.scan_poses,
                                result.trajectory.positions[:, :2])
            written += ["trajectory.png", "scan_map.png"]
            if mcap:
                with ResultsBag(staged / RESULTS_MCAP, namespace="ndt_odom") as bag:
                    write_ndt_odom_results(bag, result)
                written.append(RESULTS_MCAP)
        (staged / "summary.json").write_text(json.dumps(result.summary, indent=2) + "\n")
        written.append("summary.json")
    return [Path(out_dir) / name for name in written]


def write_ndt_odom_results(bag: ResultsBag, result: NdtOdomResult) -> None:
    """In the odometry frame: /trajectory (NDT), /odometry and /ground_truth (when the bag had them) as paths,
    /tf (odometry frame -> base at each scan) and /tf_static (base -> laser), the scans at their stamps,
    and /cloud_map: every scan's points at their NDT pose, one per 5 cm voxel, at the laser's height."""
    from bagtools.cloud import MapCloud, voxel_average
    from bagtools.commands.ndt_odom.plots import scans_in_frame

    s = result.summary
    frame, base, scan_frame = s.get("odometry_frame", "odom"), s.get("base_frame"), s.get("scan_frame")
    trajectory = result.trajectory
    if trajectory is None or not base:
        return
    for topic, traj in (("/trajectory", trajectory), ("/odometry", result.odometry),
                        ("/ground_truth", result.ground_truth)):
        if traj is not None:
            bag.path(topic, traj.stamps_ns, traj.poses, frame)
    bag.robot(frame, base, trajectory.stamps_ns, trajectory.poses, {scan_frame: result.T_base_scan} if scan_frame else {})
    xy = scans_in_frame(result.scan_points, result.scan_poses)
    points = np.column_stack([xy, np.full(len(xy), result.T_base_scan[2, 3])]).astype(np.float32)
    bag.point_cloud("/cloud_map", voxel_average(MapCloud(points), CLOUD_MAP_VOXEL_M).points, frame)
    if result.scans:
        bag.scans(s.get("topic", "/scan"), result.scans)
