"""rosbag2 (MCAP) writing for the simulator: message builders, metadata per distro and the bag writer."""

from bagtools_simulate.writer.bag import DEFAULT_ROS_DISTRO, ROS_DISTROS, TOPICS, SimBagWriter, is_rosbag2_output, typestore_for
from bagtools_simulate.writer.messages import MessageBuilder

__all__ = ["DEFAULT_ROS_DISTRO", "ROS_DISTROS", "TOPICS", "MessageBuilder", "SimBagWriter", "is_rosbag2_output",
           "typestore_for"]
