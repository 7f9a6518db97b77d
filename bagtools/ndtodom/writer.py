"""Writing a laser-odometry run's files together, atomically."""

from __future__ import annotations

import json
from pathlib import Path

from bagtools.ndtodom.pipeline import NdtOdomResult
from bagtools.ndtodom.plots import render_scan_map_png, render_trajectories_png
from bagtools.outputs import OutputDir
from bagtools.trajectory import tum_text

#: Every file the command may write (any existing one is refused without --force).
NDT_ODOM_FILES = ["trajectory.tum", "odometry.tum", "ground_truth.tum", "trajectory.png", "scan_map.png", "summary.json"]


def write_ndt_odom(result: NdtOdomResult, out_dir: str | Path, force: bool = False) -> list[Path]:
    """Write what the run computed into ``out_dir``, all or nothing; returns the paths written.

    trajectory.tum, trajectory.png and scan_map.png need at least one scan;
    odometry.tum and ground_truth.tum are written when the bag had them;
    summary.json always.
    """
    frame = result.summary.get("odometry_frame", "odom")
    body = result.summary.get("base_frame")
    written: list[str] = []
    with OutputDir(out_dir, NDT_ODOM_FILES, force) as staged:
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
        (staged / "summary.json").write_text(json.dumps(result.summary, indent=2) + "\n")
        written.append("summary.json")
    return [Path(out_dir) / name for name in written]
