"""The grid pipeline with poses given in memory (what slam uses) equals the same poses read from a TUM file."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from bagtools.commands.grid import GridMapOptions, GridMapPipeline
from bagtools.io import open_bag
from bagtools.simtruth import read_ground_truth
from bagtools.trajectory import Trajectory, write_tum
from tests.conftest import FIXTURES


def test_given_trajectory_maps_like_its_tum_file(tmp_path: Path) -> None:
    bag = FIXTURES / "sim_random_nocloud_20s"
    with open_bag(bag) as reader:
        stamps, T_map_base, _ = read_ground_truth(reader)
    shifted = T_map_base.copy()
    shifted[:, 0, 3] += 0.5  # not the ground truth: the grid must follow the poses it is given
    trajectory = Trajectory(stamps, shifted)
    write_tum(tmp_path / "traj.tum", trajectory)
    from_file = GridMapPipeline(bag, GridMapOptions(frame="odom", poses=str(tmp_path / "traj.tum"))).run()
    given = GridMapPipeline(bag, GridMapOptions(frame="odom", poses="in memory"), trajectory=trajectory).run()
    assert given.summary["scans_used"] == from_file.summary["scans_used"] > 90
    assert np.allclose(given.grid.grid_location_in_world, from_file.grid.grid_location_in_world, atol=1e-6)
    assert np.allclose(given.grid.log_odds, from_file.grid.log_odds, atol=1e-4)
    assert np.allclose(given.scan_path_xy, from_file.scan_path_xy, atol=1e-6)
    truth = GridMapPipeline(bag, GridMapOptions(frame="odom", poses="in memory"),
                            trajectory=Trajectory(stamps, T_map_base)).run()
    assert not np.allclose(truth.scan_path_xy, given.scan_path_xy, atol=0.1)
