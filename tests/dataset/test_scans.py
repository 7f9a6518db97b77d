"""The one dataset reader: damaged or odd scans and clouds are skipped or flagged, counted, and said once per kind."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from bagtools.dataset import ScanStream, SensorStream
from bagtools.errors import TopicError
from bagtools.io import open_bag
from tests.conftest import make_cloud, make_scan, write_bag

T0 = 1_700_000_000_000_000_000
STEP = 200_000_000


def scan_bag(tmp_path: Path, scans: list) -> Path:
    msgs = [("/scan", "sensor_msgs/msg/LaserScan", T0 + i * STEP, m) for i, m in enumerate(scans)]
    return write_bag(tmp_path / "scans", msgs)


def good(i: int, ranges=None):
    return make_scan(T0 + i * STEP, np.full(360, 2.0) if ranges is None else ranges)


def read(path: Path, **kw):
    with open_bag(path) as bag:
        stream = ScanStream(bag, "/scan", desc=None, **kw)
        items = list(stream)
    return items, stream


def test_unusable_headers_are_skipped_and_said(tmp_path: Path) -> None:
    zero = good(1)
    zero.angle_increment = 0.0
    nan = good(2)
    nan.angle_increment = float("nan")
    inf_min = good(3)
    inf_min.angle_min = float("inf")
    items, stream = read(scan_bag(tmp_path, [good(0), zero, nan, inf_min, good(4)]))
    assert [m.scan.stamp_ns for m in items] == [T0, T0 + 4 * STEP]
    assert sum(stream.skipped.values()) == 3
    warnings = stream.warnings()
    assert any("angle_increment is 0" in w for w in warnings)
    assert sum("not finite" in w for w in warnings) == 2


def test_implausible_limits_are_noted_and_their_returns_ignored(tmp_path: Path) -> None:
    huge = good(0, np.r_[np.full(180, 1e30), np.full(180, 2.0)])
    huge.range_max = float("inf")
    negative = good(1, np.r_[np.full(180, -1.0), np.full(180, 2.0)])
    negative.range_min = -5.0
    flipped = good(2)
    flipped.angle_increment = -flipped.angle_increment  # header says angle_max > angle_min
    items, stream = read(scan_bag(tmp_path, [huge, negative, flipped]))
    assert [int(m.scan.valid.sum()) for m in items] == [180, 180, 360]
    assert all(np.abs(m.scan.points_xy()).max() <= 2.0 + 1e-6 for m in items)
    text = " ".join(stream.warnings())
    assert "range_max inf m is implausible" in text and "range_min -5 m is not a distance" in text
    assert "opposite sign" in text


def test_time_going_backwards_and_empty_scans_skipped(tmp_path: Path) -> None:
    scans = [good(0), good(2), good(1), good(3, np.full(360, np.nan)), good(4)]
    items, stream = read(scan_bag(tmp_path, scans), increasing=True, min_returns=5)
    assert [m.scan.stamp_ns for m in items] == [T0, T0 + 2 * STEP, T0 + 4 * STEP]
    assert stream.skipped == {"stamp not after the previous scan": 1, "fewer than 5 valid ranges": 1}
    assert any("time going backwards" in w for w in stream.warnings())


def test_missing_or_wrong_topic_names_the_candidates(tmp_path: Path) -> None:
    path = scan_bag(tmp_path, [good(0)])
    with open_bag(path) as bag, pytest.raises(TopicError, match="LaserScan topics: /scan"):
        ScanStream(bag, "/front")


def test_clouds_with_bad_layout_or_wild_points(tmp_path: Path) -> None:
    xyz = np.array([[1.0, 2.0, 3.0], [1e30, 0.0, 0.0], [4.0, 5.0, 6.0]])
    ok = make_cloud(T0, xyz)
    short = make_cloud(T0 + STEP, xyz)
    short.point_step = 8  # smaller than x, y, z need
    msgs = [("/cloud", "sensor_msgs/msg/PointCloud2", T0, ok), ("/cloud", "sensor_msgs/msg/PointCloud2", T0 + STEP, short)]
    with open_bag(write_bag(tmp_path / "clouds", msgs)) as bag:
        stream = SensorStream(bag, "/cloud", desc=None)
        clouds = list(stream)
    assert len(clouds) == 1 and clouds[0].points.shape == (2, 3)
    text = " ".join(stream.warnings())
    assert "1 cloud(s) on /cloud skipped" in text and "does not fit in point_step 8" in text
    assert "1 point(s) on /cloud dropped" in text
