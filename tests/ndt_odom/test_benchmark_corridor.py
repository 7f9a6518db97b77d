"""The front end in a long featureless corridor of a classic benchmark log (``../shared/data/benchmark``; skipped
when absent).

ACES scans 5050-5200 (30 s): the robot turns, stands still for a few scans,
then drives about 10 m down a corridor whose walls say nothing of where along it
the robot is. Without odometry only the motion model knows; the scans must not
talk it out of it. Before the refinement kept out of directions its cost does
not constrain, the pose slid back along the corridor while the robot stood, the
constant-velocity guess learned that backward speed, and the front end ended
1.3 m from its start instead of 10 m (the map broke: relations off by 6.7 m).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from bagtools.commands.ndt_odom import NdtOdomOptions, run_front_end
from bagtools.transforms import se2_between, tform2pose
from tests.conftest import REPO, ros1_scan_slice

ACES = REPO.parent / "shared" / "data" / "benchmark" / "aces.bag"
FIRST, LAST = 5050, 5200


@pytest.fixture(scope="module")
def aces_corridor(tmp_path_factory) -> Path:
    """ACES scans FIRST..LAST - 1 with the odometry and tf over that time and the laser's mount (ROS 1)."""
    if not ACES.is_file():
        pytest.skip(f"benchmark logs not available: {ACES} does not exist")
    return ros1_scan_slice(ACES, tmp_path_factory.mktemp("aces") / "aces_corridor.bag", FIRST, LAST)


def test_the_front_end_does_not_slide_along_a_featureless_corridor(aces_corridor: Path) -> None:
    """Scans only: the distance from the first pose to the last agrees with the wheel odometry's (which holds
    over 10 m of straight corridor to a few per cent)."""
    scans_only = run_front_end(aces_corridor, NdtOdomOptions(use_odometry=False))
    wheels = run_front_end(aces_corridor, NdtOdomOptions(use_odometry=True)).odometry
    poses = np.array([s.pose for s in scans_only.front_end.steps])
    odom = tform2pose(wheels.poses).reshape(-1, 3)
    assert len(poses) == len(odom) == LAST - FIRST
    moved = np.hypot(*se2_between(poses[0], poses[-1])[:2])
    driven = np.hypot(*se2_between(odom[0], odom[-1])[:2])
    assert driven > 8.0
    assert abs(moved - driven) < 0.1 * driven, (moved, driven)
