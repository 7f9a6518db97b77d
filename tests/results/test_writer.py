"""results.mcap: every message decodes from its embedded schema (as Foxglove does), with the right values."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from bagtools.grid import OccupancyGrid
from bagtools.io import decode_laserscan, decode_pointcloud2, open_bag
from bagtools.results import Markers, ResultsBag
from bagtools.transforms import pose2tform
from tests.conftest import make_scan

T0 = 1_700_000_000_000_000_000


def decode_all(path: Path) -> dict[str, list[tuple[int, object]]]:
    """Every message of an MCAP, decoded by mcap-ros2-support from the schemas in the file, in log-time order."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    out: dict[str, list[tuple[int, object]]] = {}
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        last = -1
        for schema, channel, message, decoded in reader.iter_decoded_messages(log_time_order=False):
            assert message.log_time >= last  # the file itself is in log-time order
            last = message.log_time
            out.setdefault(channel.topic, []).append((message.log_time, decoded))
    return out


def channel_metadata(path: Path) -> dict[str, dict[str, str]]:
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    return {c.topic: dict(c.metadata) for c in summary.channels.values()}


@pytest.fixture
def grid() -> OccupancyGrid:
    g = OccupancyGrid(1.0, 0.5, 10.0, (-0.3, 2.0))  # 5 rows x 10 cols of 0.1 m
    for _ in range(5):
        g.insert_ray(np.array([-0.25, 2.25, 0.0]), np.array([0.5]), np.array([0.0]), 3.0)  # free cells, one hit
    return g


def test_every_message_decodes_with_the_right_values(tmp_path: Path, grid: OccupancyGrid) -> None:
    stamps = T0 + np.arange(3) * 200_000_000
    T_map_base = pose2tform(np.array([[0.0, 0.0, 0.0], [0.5, 0.1, 0.2], [1.0, 0.3, 0.4]]))
    T_base_scan = pose2tform(np.array([-0.064, 0.0, 0.0]))
    scans = [decode_laserscan(make_scan(int(s), np.full(90, 2.0, dtype=np.float32))) for s in stamps]
    path = tmp_path / "results.mcap"
    with ResultsBag(path) as bag:
        bag.occupancy_grid(grid, "map")
        bag.path("/trajectory", stamps, T_map_base, "map")
        bag.robot("map", "base_link", stamps, T_map_base, {"base_scan": T_base_scan})
        bag.scans("/scan", scans)
        bag.point_cloud("/cloud_map", np.array([[1, 2, 3], [4, 5, 6]]), "map", np.array([7.0, 8.0]),
                        np.array([[255, 0, 0], [0, 0, 9]]))
        bag.clouds("/points", [(int(stamps[1]), "base_scan", np.ones((4, 3)), None, None)])
        bag.markers("/loop_closures", "map", [Markers("loops", "line_list", np.array([[0, 0], [1, 0.3]]))])
    msgs = decode_all(path)
    assert set(msgs) == {"/map", "/trajectory", "/tf", "/tf_static", "/scan", "/cloud_map", "/points", "/loop_closures"}
    # latched messages at the start: the first scan's stamp
    for topic in ("/map", "/trajectory", "/tf_static", "/cloud_map", "/loop_closures"):
        assert [t for t, _ in msgs[topic]] == [T0]

    (_, occ), = msgs["/map"]
    assert (occ.header.frame_id, occ.info.width, occ.info.height) == ("map", 10, 5)
    assert occ.info.resolution == pytest.approx(0.1)
    assert (occ.info.origin.position.x, occ.info.origin.position.y) == pytest.approx((-0.3, 2.0))
    data = np.asarray(occ.data, dtype=np.int8).reshape(5, 10)
    assert np.array_equal(data, np.flipud(np.select([grid.occupancy_matrix("ternary") == 1,
                                                     grid.occupancy_matrix("ternary") == 0], [100, 0], -1)))
    assert set(np.unique(data)) == {-1, 0, 100} and data[2, 5] == 100  # the hit, row 2 from the bottom

    (_, path_msg), = msgs["/trajectory"]
    assert len(path_msg.poses) == 3 and path_msg.poses[2].pose.position.x == pytest.approx(1.0)
    assert path_msg.poses[2].header.stamp.sec * 10**9 + path_msg.poses[2].header.stamp.nanosec == stamps[2]
    assert path_msg.poses[1].pose.orientation.z == pytest.approx(np.sin(0.1))

    tf_times = [t for t, _ in msgs["/tf"]]
    assert tf_times == stamps.tolist()
    ts = msgs["/tf"][1][1].transforms[0]
    assert (ts.header.frame_id, ts.child_frame_id, ts.transform.translation.x) == ("map", "base_link", 0.5)
    static = msgs["/tf_static"][0][1].transforms[0]
    assert (static.header.frame_id, static.child_frame_id, static.transform.translation.x) == ("base_link", "base_scan", -0.064)

    assert [t for t, _ in msgs["/scan"]] == stamps.tolist()
    scan = msgs["/scan"][0][1]
    assert scan.header.frame_id == "base_scan" and len(scan.ranges) == 90
    assert scan.angle_increment == pytest.approx(np.pi / 180) and scan.range_max == pytest.approx(3.5)

    cloud = msgs["/cloud_map"][0][1]
    assert [f.name for f in cloud.fields] == ["x", "y", "z", "intensity", "rgb"] and cloud.width == 2
    markers = msgs["/loop_closures"][0][1].markers
    assert markers[0].type == 5 and len(markers[0].points) == 2 and markers[0].header.frame_id == "map"


def test_qos_latched_where_published_once(tmp_path: Path, grid: OccupancyGrid) -> None:
    path = tmp_path / "results.mcap"
    with ResultsBag(path) as bag:
        bag.occupancy_grid(grid, "map")
        bag.tf("map", "base", np.array([T0]), np.eye(4)[None])
        bag.tf_static([("base", "laser", np.eye(4))])
    meta = channel_metadata(path)
    assert "durability: 1" in meta["/map"]["offered_qos_profiles"]  # transient local, as map_server offers
    assert "durability: 1" in meta["/tf_static"]["offered_qos_profiles"]
    assert "durability: 2" in meta["/tf"]["offered_qos_profiles"] and "depth: 100" in meta["/tf"]["offered_qos_profiles"]
    assert meta["/map"]["topic_type_hash"].startswith("RIHS01_")


def test_bagtools_reads_its_own_results(tmp_path: Path) -> None:
    path = tmp_path / "results.mcap"
    with ResultsBag(path) as bag:
        bag.clouds("/points", [(T0 + k, "lidar", np.full((3, 3), k), np.arange(3.0), np.full((3, 3), 40 + k))
                               for k in range(4)])
    with open_bag(path) as reader:
        assert reader.topics["/points"].count == 4
        clouds = [decode_pointcloud2(r.msg, attributes=True) for r in reader.messages(["/points"])]
    assert clouds[3].points.tolist() == [[3, 3, 3]] * 3 and clouds[3].rgb.tolist() == [[43, 43, 43]] * 3
    assert clouds[0].intensity.tolist() == [0, 1, 2] and clouds[2].stamp_ns == T0 + 2


def test_an_error_leaves_no_file(tmp_path: Path) -> None:
    path = tmp_path / "results.mcap"
    with pytest.raises(RuntimeError):
        with ResultsBag(path) as bag:
            bag.tf("map", "base", np.array([T0]), np.eye(4)[None])
            raise RuntimeError("boom")
    assert not path.exists()
    with pytest.raises(ValueError, match="already holds"):
        with ResultsBag(path) as bag:
            bag.tf_static([("a", "b", np.eye(4))])
            bag.path("/tf_static", np.array([T0]), np.eye(4)[None], "map")
    assert not path.exists()
