"""The simulated TurtleBot3 Waffle: routes, controller, wheel odometry and the AMCL-like map -> odom."""

from bagtools_simulate.robot.amcl import MapToOdom, amcl_map_to_odom
from bagtools_simulate.robot.controller import Limits, Motion, drive
from bagtools_simulate.robot.odometry import ODOM_NOISE_LEVELS, Odometry, wheel_odometry
from bagtools_simulate.robot.routes import ROUTE_NAMES, Route, make_route

__all__ = [
    "ODOM_NOISE_LEVELS",
    "ROUTE_NAMES",
    "Limits",
    "MapToOdom",
    "Motion",
    "Odometry",
    "Route",
    "amcl_map_to_odom",
    "drive",
    "make_route",
    "wheel_odometry",
]
