"""bagtools: tools over recorded ROS bags (MCAP, rosbag2 sqlite3, ROS 1) and CARMEN logs.

The layers, bottom up (nothing imports upward or sideways; docs/architecture.md, checked by
tests/test_architecture.py):

- ``io``: one reader over every bag format (``open_bag``), CARMEN logs included, and decoders to numpy arrays;
- ``transforms``: MATLAB-style rotations and transforms (quaternions [w x y z]);
- ``tf``: a time-indexed tf buffer with tf2's semantics (``TfBuffer``), repairs and ``tf echo``;
- ``dataset``: the streams the algorithms read (scans in recording order, odometry);
- ``trajectory``: trajectories, TUM files, evo's APE/RPE, the benchmarks' relations metric, alignment;
- ``scan_matching``: 2D NDT and correlative (branch and bound) scan matching;
- ``cloud``: point clouds as data, voxel filters;
- ``grid``: log-odds occupancy grids, ray casting, nav2 maps, a bag's grid at known poses;
- ``odometry``: the laser-odometry front end that ``slam``, ``ndt-odom`` and ``localize`` share, and a bag
  through it;
- ``pose_graph``: loop closure (constraint search) and the GTSAM pose graph;
- ``commands``: one module or package per command, named as the command is (``info``, ``grid``, ``map_cloud``,
  ``ndt_odom``, ``slam``, ``localize``, ``export``): its own pipeline and its writer;
- ``results``: results.mcap writers (to open beside the bag in Foxglove);
- ``batch``: many bags through one command on a Dask cluster;
- ``cli``: the thin click shell (``bagtools --help``).

Modules: ``outputs`` (atomic writes, --force, staging), ``errors``, ``limits``
(memory budget), ``progress``, ``figures``, ``stamps`` (stamps written as text, read exactly), ``simtruth`` (a
bag's /ground_truth). The simulator installs as
``bagtools_simulate``.
"""

__version__ = "0.1.0"
