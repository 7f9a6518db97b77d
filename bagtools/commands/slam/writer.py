"""Writing a SLAM run's files together, atomically (all or nothing, see :mod:`bagtools.outputs`)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from bagtools.grid import nav2_map_files
from bagtools.outputs import OutputDir
from bagtools.results import RESULTS_MCAP, Markers, ResultsBag, run_outputs
from bagtools.commands.slam.pipeline import SLAM_FRAME, SlamResult
from bagtools.grid.render import render_slam_map_png
from bagtools.trajectory import tum_text

#: Every file the command may write (any existing one is refused without --force).
SLAM_FILES = ["trajectory.tum", "odometry.tum", "ground_truth.tum", "pose_graph.g2o", "map.pgm", "map.yaml", "map.png",
              "summary.json", RESULTS_MCAP]


def write_slam(result: SlamResult, out_dir: str | Path, force: bool = False, mcap: bool = True) -> list[Path]:
    """Write the run into ``out_dir``; returns the paths written (ground_truth.tum only for bags with /ground_truth).

    trajectory.tum (optimized, every scan), odometry.tum (front end),
    pose_graph.g2o (keyframes and constraints at the optimized estimate),
    map.pgm + map.yaml (nav2 map_server), map.png, summary.json, and with
    ``mcap`` results.mcap (see :func:`write_slam_results`).
    """
    written: list[str] = []
    s = result.summary
    base = _base_frame(result)
    with OutputDir(out_dir, run_outputs(SLAM_FILES, mcap), force) as staged:
        for name, traj in (("trajectory.tum", result.trajectory), ("odometry.tum", result.odometry),
                           ("ground_truth.tum", result.ground_truth)):
            if traj is not None:
                (staged / name).write_text(tum_text(traj, SLAM_FRAME, base))
                written.append(name)
        (staged / "pose_graph.g2o").write_text(result.back_end.graph.g2o_text())
        for name, data in nav2_map_files(result.grid, "map").items():
            (staged / name).write_bytes(data)
        title = (f"{s.get('topic', '')}: {s.get('keyframes', 0)} keyframes, "
                 f"{s.get('loop_closure', {}).get('accepted', 0)} loop closures, {result.grid.cell_size_m:g} m/cell")
        (staged / "map.png").write_bytes(render_slam_map_png(result.grid, result.trajectory.positions[:, :2],
                                                             result.loop_segments, title))
        (staged / "summary.json").write_text(json.dumps(s, indent=2) + "\n")
        written += ["pose_graph.g2o", "map.pgm", "map.yaml", "map.png", "summary.json"]
        if mcap:
            with ResultsBag(staged / RESULTS_MCAP, namespace="slam") as bag:
                write_slam_results(bag, result)
            written.append(RESULTS_MCAP)
    return [Path(out_dir) / name for name in written]


def _base_frame(result: SlamResult) -> str | None:
    front = result.front_end
    return (front.summary.get("base_frame") or None) if front is not None else None


def map_to_odom(result: SlamResult) -> tuple[str, np.ndarray, np.ndarray] | None:
    """(the bag's odometry frame, stamps (N,), T_slam_odom (N,4,4)): REP 105's map -> odom correction at each scan,
    T_slam_base T_odom_base^-1, which hangs the bag's own tree under the SLAM map; None when the run used no wheel
    odometry or the bag's odometry frame already has a parent (a localizer's map), which keeps its own tree."""
    front = result.front_end
    wheels = front.odometry if front is not None else None
    odom_frame = front.summary.get("odometry_frame") if front is not None else None
    if wheels is None or not odom_frame or front.summary.get("odometry_frame_parent"):
        return None
    if not np.array_equal(wheels.stamps_ns, result.trajectory.stamps_ns):
        return None
    return odom_frame, wheels.stamps_ns, result.trajectory.poses @ np.linalg.inv(wheels.poses)


def write_slam_results(bag: ResultsBag, result: SlamResult) -> None:
    """In the map frame: /map, /trajectory (optimized), /odometry (the laser odometry) and /ground_truth as paths,
    /tf (map -> base at each scan) and /tf_static (base -> laser), the scans at their stamps, and the accepted loop
    closures as a MarkerArray of line segments between their keyframes. When the bag's odometry frame has no parent,
    /tf also carries slam_map -> odom (:func:`map_to_odom`): played beside the bag, one tree."""
    bag.occupancy_grid(result.grid, SLAM_FRAME)
    for topic, traj in (("/trajectory", result.trajectory), ("/odometry", result.odometry),
                        ("/ground_truth", result.ground_truth)):
        if traj is not None:
            bag.path(topic, traj.stamps_ns, traj.poses, SLAM_FRAME)
    front = result.front_end
    base = _base_frame(result)
    if front is None or not base:
        return
    scan_frame = front.summary.get("scan_frame")
    bag.robot(SLAM_FRAME, base, result.trajectory.stamps_ns, result.trajectory.poses,
              {scan_frame: front.T_base_scan} if scan_frame and scan_frame != base else {})
    ties = map_to_odom(result)
    if ties is not None:
        bag.tf(SLAM_FRAME, *ties)
    if front.scans:
        bag.scans(front.summary.get("topic", "/scan"), front.scans)
    if len(result.loop_segments):
        ends = np.column_stack([result.loop_segments.reshape(-1, 2), np.zeros(2 * len(result.loop_segments))])
        bag.markers("/loop_closures", SLAM_FRAME, [Markers("loop_closures", "line_list", ends)])
