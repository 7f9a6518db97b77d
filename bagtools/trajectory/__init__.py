"""Trajectories: stamped poses, TUM files (evo's format), their errors, pose relations (Kümmerle et al.)."""

from bagtools.trajectory.metrics import ErrorStats, ape_translation, associate, rpe_frames, rpe_translation
from bagtools.trajectory.relations import (
    Relations, read_relations, relation_errors, relations_from_trajectory, relations_text,
)
from bagtools.trajectory.tum import Trajectory, read_tum, read_tum_frames, tum_text, write_tum

__all__ = ["ErrorStats", "Relations", "Trajectory", "ape_translation", "associate", "read_relations", "read_tum",
           "relation_errors", "relations_from_trajectory", "relations_text", "rpe_frames", "rpe_translation",
           "read_tum_frames", "tum_text", "write_tum"]
