"""A command's results as one ROS 2 MCAP (``results.mcap``) for Foxglove, RViz (``ros2 bag play``) and rosbag2."""

from bagtools.results.writer import LATCHED, RESULTS_MCAP, Markers, ResultsBag, run_outputs

__all__ = ["LATCHED", "RESULTS_MCAP", "Markers", "ResultsBag", "run_outputs"]
