"""The reference poses of a bag (/ground_truth): what is dropped, and jumps said."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from bagtools.io import open_bag
from bagtools.simtruth import read_ground_truth
from tests.ndt_odom.conftest import make_odometry, write_bag


def test_a_reference_that_jumps_1_km_is_said_and_a_smooth_one_is_not(tmp_path: Path) -> None:
    t0 = 1_700_000_000_000_000_000

    def bag_with(xs: np.ndarray, name: str) -> Path:
        msgs = []
        for i, x in enumerate(xs):
            T = np.eye(4)
            T[0, 3] = x
            t = t0 + i * 100_000_000
            msgs.append(("/ground_truth", "nav_msgs/msg/Odometry", t, make_odometry(t, "map", "base_link", T)))
        return write_bag(tmp_path / name, msgs)

    xs = 0.05 * np.arange(50)
    for name, values, said in (("smooth", xs, False), ("jump", np.where(np.arange(50) >= 30, xs + 1000.0, xs), True)):
        warnings: list[str] = []
        with open_bag(bag_with(values, name)) as bag:
            stamps, T, child = read_ground_truth(bag, warnings=warnings)
        assert len(stamps) == 50 and child == "base_link"
        assert any("the reference jumps 1 time(s), up to 1e+03 m in 0.1 s" in w for w in warnings) == said, warnings


def test_poses_on_a_topic_of_another_type_are_said_not_ignored(tmp_path) -> None:
    """An /amcl_pose of the wrong type (String, PoseStamped, LaserScan) was ignored without a word."""
    from bagtools.io import open_bag
    from bagtools.simtruth import read_poses
    from tests.conftest import TYPESTORE, write_bag

    String = TYPESTORE.types["std_msgs/msg/String"]
    bag_path = write_bag(tmp_path / "bag", [("/amcl_pose", "std_msgs/msg/String", 1_000, String(data="x"))])
    warnings: list[str] = []
    with open_bag(bag_path) as bag:
        assert read_poses(bag, "/amcl_pose", warnings) is None
    assert warnings == ["/amcl_pose has type std_msgs/msg/String, not nav_msgs/Odometry or "
                        "geometry_msgs/PoseWithCovarianceStamped: its poses are not read"]
