"""Simulated sensors: the LDS-01 lidar, the R200-like depth camera and the IMU."""

from bagtools_simulate.sensors.depth_camera import DepthCamera
from bagtools_simulate.sensors.imu import Imu, ImuSamples
from bagtools_simulate.sensors.lidar import Lidar

__all__ = ["DepthCamera", "Imu", "ImuSamples", "Lidar"]
