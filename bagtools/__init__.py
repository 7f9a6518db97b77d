"""bagtools: tools over recorded ROS bags (MCAP, rosbag2 sqlite3, ROS 1) and CARMEN logs.

The layers, bottom up (nothing imports upward):

- ``io``: one reader over every bag format (``open_bag``), CARMEN logs included, and decoders to numpy arrays;
- ``transforms``: MATLAB-style rotations and transforms (quaternions [w x y z]);
- ``tf``: a time-indexed tf buffer with tf2's semantics (``TfBuffer``), repairs and ``tf echo``;
- ``dataset``: the streams the algorithms read (scans in recording order, odometry);
- ``trajectory``: trajectories, TUM files, evo's APE/RPE and the benchmarks' relations metric;
- ``scan_matching``: 2D NDT and correlative (branch and bound) scan matching;
- ``grid``: log-odds occupancy grids, ray casting and the free space rays saw;
- ``odometry``: the laser-odometry front end that ``slam``, ``ndt-odom`` and ``localize`` share;
- ``gridmap``, ``cloudmap``: maps from known poses (``grid``, ``map-cloud``);
- ``ndtodom``: the ``ndt-odom`` command's pipeline (a bag through the front end, its outputs);
- ``localize``: where scans are in a map the robot already has (so far the global search, ``GlobalLocalizer``);
- ``slam``: loop closure, the GTSAM pose graph, the SLAM pipeline and ``eval``;
- ``results``: results.mcap writers (to open beside the bag in Foxglove);
- ``export``: any topic to CSV, NPZ or Parquet;
- ``batch``: many bags through one command on a Dask cluster;
- ``cli``: the thin click shell (``bagtools --help``).

Modules: ``baginfo`` (``bagtools info``), ``outputs`` (atomic writes, --force, staging), ``errors``, ``limits``
(memory budget), ``progress``, ``figures``, ``simtruth`` (a bag's /ground_truth). The simulator installs as
``bagtools_simulate``.
"""

__version__ = "0.1.0"
