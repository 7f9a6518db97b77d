"""Bags and front-end runs for the SLAM tests: a long simulated figure eight, and the real CSAIL log."""

from __future__ import annotations

from pathlib import Path

import pytest

from bagtools_simulate.pipeline import SimConfig, simulate_bag
from tests.conftest import REAL_DIR
from tests.slam.standin import Drift, front_end_from_truth

#: The stand-in's drift on simulated bags: about what NDT laser odometry does there (a few mm per keyframe).
SIM_DRIFT = Drift(scale=0.01, heading_bias_rad_per_m=0.003, noise_m=0.003, noise_rad=0.002)
#: The stand-in's drift on the CSAIL log: end point some 10 m off after its 380 m.
CSAIL_DRIFT = Drift(scale=0.01, heading_bias_rad_per_m=0.002, noise_m=0.01, noise_rad=0.004)


@pytest.fixture(scope="session")
def figure8_bag(tmp_path_factory) -> Path:
    """A 200 s figure eight with high wheel-odometry noise, no camera (about 1000 scans, 35 m)."""
    path = tmp_path_factory.mktemp("slam_sim") / "figure8"
    simulate_bag(path, SimConfig(duration_s=200.0, route="figure8", odom_noise="high", cloud=False, seed=3))
    return path


@pytest.fixture(scope="session")
def figure8_front(figure8_bag: Path):
    return front_end_from_truth(figure8_bag, drift=SIM_DRIFT)


@pytest.fixture(scope="session")
def csail_odom() -> Path:
    path = REAL_DIR / "csail_odom"
    if not path.is_dir():
        pytest.skip(f"real bags not available: {path} does not exist")
    return path
