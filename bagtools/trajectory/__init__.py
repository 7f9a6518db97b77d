"""Trajectories: stamped poses, TUM files (evo's format)."""

from bagtools.trajectory.metrics import ErrorStats, ape_translation, associate, rpe_frames, rpe_translation
from bagtools.trajectory.tum import Trajectory, read_tum, tum_text, write_tum

__all__ = ["ErrorStats", "Trajectory", "ape_translation", "associate", "read_tum", "rpe_frames", "rpe_translation",
           "tum_text", "write_tum"]
