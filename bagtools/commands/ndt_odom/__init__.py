"""Laser odometry by 2D NDT scan matching (``bagtools ndt-odom``)."""

from bagtools.odometry.options import INIT_MODES, REFERENCE_MODES, NdtOdomOptions
from bagtools.odometry.pipeline import NdtOdomPipeline, NdtOdomResult, run_front_end
from bagtools.commands.ndt_odom.plots import render_scan_map_png, render_trajectories_png, scans_in_frame
from bagtools.commands.ndt_odom.writer import NDT_ODOM_FILES, write_ndt_odom

__all__ = [
    "INIT_MODES", "NDT_ODOM_FILES", "REFERENCE_MODES",
    "NdtOdomOptions", "NdtOdomPipeline", "NdtOdomResult", "render_scan_map_png", "run_front_end", "render_trajectories_png", "scans_in_frame", "write_ndt_odom",
]
