"""Simulated sensors: the LDS-01 lidar, the R200-like depth camera and the IMU."""

from simulate.sensors.depth_camera import DepthCamera
from simulate.sensors.imu import Imu, ImuSamples
from simulate.sensors.lidar import Lidar

__all__ = ["DepthCamera", "Imu", "ImuSamples", "Lidar"]
