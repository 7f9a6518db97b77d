"""TurtleBot3 simulator: writes realistic rosbag2 bags without ROS or Gazebo.

Entry point: :func:`simulate.pipeline.simulate_bag` (the ``bagtools simulate`` command).
"""
