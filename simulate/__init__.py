"""TurtleBot3 simulator: writes realistic rosbag2 bags without ROS or Gazebo.

Entry point: :func:`bagtools_simulate.pipeline.simulate_bag` (the ``bagtools simulate`` command).
"""
