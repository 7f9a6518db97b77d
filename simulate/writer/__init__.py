"""rosbag2 (MCAP) writing for the simulator: message builders and the bag writer."""

from simulate.writer.bag import ROS_DISTROS, TOPICS, SimBagWriter, is_rosbag2_output, typestore_for
from simulate.writer.messages import MessageBuilder

__all__ = ["ROS_DISTROS", "TOPICS", "MessageBuilder", "SimBagWriter", "is_rosbag2_output", "typestore_for"]
