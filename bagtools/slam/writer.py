"""Writing a SLAM run's files together, atomically (all or nothing, see :mod:`bagtools.outputs`)."""

from __future__ import annotations

import json
from pathlib import Path

from bagtools.grid import nav2_map_files
from bagtools.outputs import OutputDir
from bagtools.slam.pipeline import SlamResult
from bagtools.slam.render import render_slam_map_png
from bagtools.trajectory import tum_text

#: Every file the command may write (any existing one is refused without --force).
SLAM_FILES = ["trajectory.tum", "odometry.tum", "ground_truth.tum", "pose_graph.g2o", "map.pgm", "map.yaml", "map.png",
              "summary.json"]


def write_slam(result: SlamResult, out_dir: str | Path, force: bool = False) -> list[Path]:
    """Write the run into ``out_dir``; returns the paths written (ground_truth.tum only for bags with /ground_truth).

    trajectory.tum (optimized, every scan), odometry.tum (front end),
    pose_graph.g2o (keyframes and constraints at the optimized estimate),
    map.pgm + map.yaml (nav2 map_server), map.png, summary.json.
    """
    written: list[str] = []
    s = result.summary
    with OutputDir(out_dir, SLAM_FILES, force) as staged:
        for name, traj in (("trajectory.tum", result.trajectory), ("odometry.tum", result.odometry),
                           ("ground_truth.tum", result.ground_truth)):
            if traj is not None:
                (staged / name).write_text(tum_text(traj))
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
    return [Path(out_dir) / name for name in written]
