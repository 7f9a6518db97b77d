"""The pose graph and what goes into it: loop search, its checks, GTSAM (Cartographer's split).

- :mod:`~bagtools.pose_graph.constraints`: the constraint search, local (within the graph's uncertainty) and
  global, the match and its covariance (its options and records in :mod:`~bagtools.pose_graph.loops`);
- :mod:`~bagtools.pose_graph.consistency`: which matches are accepted (the estimate, a second match);
- :mod:`~bagtools.pose_graph.graph`: the GTSAM pose graph (:class:`PoseGraph`), robust loop kernel;
- :mod:`~bagtools.pose_graph.backend`: :func:`build_pose_graph` walks a front end's keyframes through both.

``slam`` builds its map with it; ``localize`` smooths its track with the same search and graph.
"""

from bagtools.pose_graph.backend import BackEndOptions, BackEndResult, build_pose_graph
from bagtools.pose_graph.consistency import ConsistencyCheck
from bagtools.pose_graph.constraints import LoopClosureSearch
from bagtools.pose_graph.graph import LOOP, ODOMETRY, Constraint, Optimization, PoseGraph
from bagtools.pose_graph.loops import LoopCandidate, LoopOptions

__all__ = [
    "LOOP", "ODOMETRY", "BackEndOptions", "BackEndResult", "ConsistencyCheck", "Constraint", "LoopCandidate",
    "LoopClosureSearch", "LoopOptions", "Optimization", "PoseGraph", "build_pose_graph",
]
