"""bagtools: tools over recorded ROS bags (MCAP, rosbag2 sqlite3, ROS 1).

Subpackages: ``io`` (reading and decoding bags), ``transforms`` (MATLAB-style
rotation and transform representations), ``tf`` (time-indexed tf buffer with
tf2 semantics), ``cli`` (the click shell around the library).
"""

__version__ = "0.1.0"
