"""Laser SLAM over a bag (``bagtools slam``): the front end's keyframes, loop closure, a GTSAM pose graph, the map.

Three roles kept apart, as Cartographer does: the front end (laser odometry,
:mod:`bagtools.ndtodom`), the constraint search (:mod:`bagtools.slam.constraints`)
and the graph (:mod:`bagtools.slam.graph`, GTSAM); :mod:`bagtools.slam.backend`
runs the last two over the keyframes and :mod:`bagtools.slam.pipeline` the whole.
"""

from bagtools.slam.backend import BackEndOptions, BackEndResult, build_pose_graph
from bagtools.slam.constraints import ConsistencyCheck, LoopCandidate, LoopClosureSearch, LoopOptions
from bagtools.slam.evaluate import align_se2, ape_aligned, gap_errors, trajectory_errors
from bagtools.slam.graph import LOOP, ODOMETRY, Constraint, Optimization, PoseGraph
from bagtools.slam.pipeline import SLAM_FRAME, FrontEnd, SlamOptions, SlamPipeline, SlamResult, laser_odometry
from bagtools.slam.render import render_slam_map_png
from bagtools.slam.writer import SLAM_FILES, write_slam

__all__ = [
    "LOOP", "ODOMETRY", "SLAM_FILES", "SLAM_FRAME", "BackEndOptions", "BackEndResult", "ConsistencyCheck",
    "Constraint", "FrontEnd", "LoopCandidate", "LoopClosureSearch", "LoopOptions", "Optimization", "PoseGraph",
    "SlamOptions", "SlamPipeline", "SlamResult", "align_se2", "ape_aligned", "build_pose_graph", "gap_errors",
    "laser_odometry", "render_slam_map_png", "trajectory_errors", "write_slam",
]
