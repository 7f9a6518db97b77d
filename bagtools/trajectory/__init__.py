"""Trajectories: stamped poses, TUM files (evo's format)."""

from bagtools.trajectory.tum import Trajectory, read_tum, tum_text, write_tum

__all__ = ["Trajectory", "read_tum", "tum_text", "write_tum"]
