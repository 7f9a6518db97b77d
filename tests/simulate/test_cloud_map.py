"""The depth cloud moved to camera_depth_optical_frame (and the URDF's rotations): map-cloud is as accurate as before.

The reference numbers are map-cloud's accuracy on the same configurations simulated by the
previous simulator (commit 8c6833b, cloud in camera_rgb_optical_frame with exact optical
rotations); points, noise and poses differ in detail, the accuracy against the true world
must not.
"""

from __future__ import annotations

import pytest

from bagtools.commands.map_cloud import CloudMapOptions, CloudMapPipeline
from bagtools_simulate.pipeline import SimConfig, simulate_bag

BEFORE = {
    # 30 s lap, default settings, map frame (AMCL-like map -> odom errors dominate)
    "default_map": {"mean": 0.018528, "median": 0.010976, "p95": 0.062143},
    # 30 s figure eight, exact odometry, 80x60 clouds at 5 Hz, odom frame (geometry and depth noise only)
    "exact_odom": {"mean": 0.0056057, "median": 0.0012224, "p95": 0.026980},
}


@pytest.mark.parametrize("case", list(BEFORE))
def test_cloud_map_accuracy_against_the_true_world_is_unchanged(tmp_path, case):
    if case == "default_map":
        bag = simulate_bag(tmp_path / "bag", SimConfig(duration_s=30.0, cloud_frame="camera_depth_optical_frame")).path
        options = CloudMapOptions(sample=0.2)
    else:
        config = SimConfig(duration_s=30.0, route="figure8", odom_noise="none", cloud_size=(80, 60), cloud_rate_hz=5.0,
                           cloud_frame="camera_depth_optical_frame")
        bag = simulate_bag(tmp_path / "bag", config).path
        options = CloudMapOptions(sample=0.2, frame="odom")
    summary = CloudMapPipeline(bag, options).run().summary
    assert summary["sensor_frames"] == ["camera_depth_optical_frame"]
    accuracy = summary["accuracy_vs_truth_m"]
    for key, before in BEFORE[case].items():
        assert accuracy[key] == pytest.approx(before, rel=0.03), key
