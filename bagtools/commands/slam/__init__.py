"""Laser SLAM over a bag (``bagtools slam``): the front end's keyframes, loop closure, a GTSAM pose graph, the map.

Three roles kept apart, as Cartographer does: the front end (laser odometry,
:mod:`bagtools.odometry`), the constraint search (:mod:`bagtools.pose_graph.constraints`)
and the graph (:mod:`bagtools.pose_graph.graph`, GTSAM); :mod:`bagtools.pose_graph.backend`
runs the last two over the keyframes and :mod:`bagtools.commands.slam.pipeline` the whole.
"""

from bagtools.commands.slam.pipeline import SLAM_FRAME, FrontEnd, SlamOptions, SlamPipeline, SlamResult, laser_odometry
from bagtools.commands.slam.writer import SLAM_FILES, write_slam

__all__ = ["SLAM_FILES", "SLAM_FRAME", "FrontEnd", "SlamOptions", "SlamPipeline", "SlamResult", "laser_odometry",
           "write_slam"]
