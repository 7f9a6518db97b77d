"""Decoders: PointCloud2 layouts, LaserScan angles and validity, Odometry, TFMessage."""

from __future__ import annotations

import numpy as np
import pytest

from bagtools.io import DecodeError, decode_laserscan, decode_pointcloud2, decode_tf_message
from tests.conftest import TYPESTORE, make_cloud, make_scan, make_tf

XYZ = np.array([[1.0, 2.0, 3.0], [np.nan, 0.0, 0.0], [4.0, 5.0, 6.0], [7.0, np.inf, 9.0], [-1.5, 0.25, 1e3], [0.0, 0.0, 0.0]])
FINITE = XYZ[[0, 2, 4, 5]]


@pytest.mark.parametrize("point_step,row_pad,bigendian,dtype,height", [
    (12, 0, False, "f4", 1),   # packed
    (16, 0, False, "f4", 1),   # padded points (x y z pad), the common layout
    (32, 0, False, "f4", 2),   # organized 2x3 cloud
    (16, 5, False, "f4", 2),   # padded rows
    (16, 0, True, "f4", 1),    # big endian
    (24, 0, False, "f8", 1),   # float64 fields
    (32, 3, True, "f8", 3),    # everything at once
])
def test_pointcloud2_layouts(point_step, row_pad, bigendian, dtype, height) -> None:
    msg = make_cloud(123, XYZ, point_step=point_step, row_pad=row_pad, bigendian=bigendian, dtype=dtype, height=height)
    cloud = decode_pointcloud2(msg)
    assert cloud.points.dtype == np.float32 and cloud.points.shape == (4, 3)
    np.testing.assert_allclose(cloud.points, FINITE.astype(np.float32))
    kept = decode_pointcloud2(msg, keep_nan=True)
    assert kept.points.shape == (6, 3)
    assert cloud.stamp_ns == 123 and cloud.frame_id == "camera"


def test_pointcloud2_fields_in_any_order() -> None:
    T = TYPESTORE.types
    msg = make_cloud(0, XYZ, point_step=16)
    # Declare z at offset 0 and x at offset 8: the decoder must follow the fields, not assume x,y,z order.
    fields = [T["sensor_msgs/msg/PointField"](name=n, offset=o, datatype=7, count=1) for n, o in (("z", 0), ("y", 4), ("x", 8))]
    msg = T["sensor_msgs/msg/PointCloud2"](header=msg.header, height=1, width=6, fields=fields, is_bigendian=False,
                                            point_step=16, row_step=96, data=msg.data, is_dense=False)
    np.testing.assert_allclose(decode_pointcloud2(msg).points, FINITE[:, ::-1].astype(np.float32))


def test_pointcloud2_zero_copy_for_packed_float32() -> None:
    msg = make_cloud(0, np.ones((5, 3)), point_step=16)
    from bagtools.io.decode import _xyz_records

    records, view = _xyz_records(msg)
    assert np.shares_memory(view, msg.data) and np.shares_memory(records, msg.data)


def test_pointcloud2_errors() -> None:
    T = TYPESTORE.types
    msg = make_cloud(0, XYZ)
    no_z = T["sensor_msgs/msg/PointCloud2"](header=msg.header, height=1, width=6, fields=msg.fields[:2],
                                             is_bigendian=False, point_step=16, row_step=96, data=msg.data, is_dense=False)
    with pytest.raises(DecodeError, match="no field"):
        decode_pointcloud2(no_z)
    short = T["sensor_msgs/msg/PointCloud2"](header=msg.header, height=1, width=6, fields=msg.fields, is_bigendian=False,
                                              point_step=16, row_step=96, data=msg.data[:50], is_dense=False)
    with pytest.raises(DecodeError, match="inconsistent"):
        decode_pointcloud2(short)


def test_empty_cloud() -> None:
    cloud = decode_pointcloud2(make_cloud(0, np.empty((0, 3))))
    assert cloud.points.shape == (0, 3)


def test_laserscan_angles_validity_and_points() -> None:
    ranges = np.array([1.0, np.inf, np.nan, 0.05, 3.4, 4.0], dtype=np.float32)
    scan = decode_laserscan(make_scan(5, ranges, angle_min=-np.pi / 2, increment=np.pi / 2))
    np.testing.assert_allclose(scan.angles_rad, -np.pi / 2 + np.arange(6) * np.pi / 2)
    assert scan.valid.tolist() == [True, False, False, False, True, False]
    np.testing.assert_allclose(scan.points_xy(), [[0.0, -1.0], [3.4 * np.cos(np.pi * 1.5), 3.4 * np.sin(np.pi * 1.5)]], atol=1e-6)


def test_tf_message() -> None:
    arrays = decode_tf_message(make_tf(1_500_000_000, "/odom", "base_link", (1, 2, 3), (0, 0, 0.6, 0.8)))
    assert arrays.parent.tolist() == ["/odom"] and arrays.child.tolist() == ["base_link"]
    assert arrays.stamp_ns.tolist() == [1_500_000_000]
    np.testing.assert_allclose(arrays.translation, [[1, 2, 3]])
    np.testing.assert_allclose(arrays.rotation_xyzw, [[0, 0, 0.6, 0.8]])


def test_a_negative_header_stamp_is_an_unusable_sensor_message() -> None:
    """Before 1970: it places the data nowhere and no MCAP file can hold it (log times are unsigned)."""
    scan = make_scan(-1_500_000_000, np.full(10, 1.0, dtype=np.float32))
    with pytest.raises(DecodeError, match="LaserScan header stamp -1.500000000 s is negative"):
        decode_laserscan(scan)
    cloud = make_cloud(-1, np.zeros((3, 3)))
    with pytest.raises(DecodeError, match="PointCloud2 header stamp .* is negative"):
        decode_pointcloud2(cloud)
