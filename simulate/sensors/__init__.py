"""Simulated sensors: the LDS-01 lidar and the R200-like depth camera."""

from simulate.sensors.depth_camera import DepthCamera
from simulate.sensors.lidar import Lidar

__all__ = ["DepthCamera", "Lidar"]
