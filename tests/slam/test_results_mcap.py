"""slam's results.mcap: what Foxglove decodes from the embedded schemas (mcap-ros2-support)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from bagtools.commands.slam import SlamOptions, SlamPipeline, write_slam
from tests.conftest import FIXTURES


def decoded(path: Path) -> dict[str, list]:
    out: dict[str, list] = {}
    with path.open("rb") as f:
        for _, channel, _, msg in make_reader(f, decoder_factories=[DecoderFactory()]).iter_decoded_messages():
            out.setdefault(channel.topic, []).append(msg)
    return out


def test_results_mcap_holds_the_map_paths_scans_and_loops(tmp_path: Path) -> None:
    result = SlamPipeline(FIXTURES / "sim_lap_cloud_20s", SlamOptions(keep_scans=True)).run()
    loops = np.array([[[0.0, 0.0], [1.0, 0.5]], [[0.2, 0.1], [0.9, 0.4]]])
    write_slam(replace(result, loop_segments=loops), tmp_path / "out")
    msgs = decoded(tmp_path / "out" / "results.mcap")
    assert {"/map", "/trajectory", "/odometry", "/ground_truth", "/tf", "/tf_static", "/scan",
            "/loop_closures"} <= set(msgs)
    grid = msgs["/map"][0]
    assert grid.info.width * grid.info.height == len(grid.data) and set(np.unique(grid.data)) <= {-1, 0, 100}
    assert len(msgs["/trajectory"][0].poses) == len(result.trajectory) == len(msgs["/scan"])
    marker = msgs["/loop_closures"][0].markers[0]
    assert len(marker.points) == 4 and marker.header.frame_id == grid.header.frame_id
    first = (tmp_path / "out" / "trajectory.tum").read_text().splitlines()[0]
    assert first.startswith("# frame: ") and " body: base_footprint" in first


def test_no_mcap_writes_none(tmp_path: Path) -> None:
    result = SlamPipeline(FIXTURES / "sim_lap_cloud_20s", SlamOptions()).run()
    names = [p.name for p in write_slam(result, tmp_path / "out", mcap=False)]
    assert "results.mcap" not in names and not (tmp_path / "out" / "results.mcap").exists()
