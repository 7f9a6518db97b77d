"""Clouds keep what the sensor gave: intensity and colour through decoding, sampling, voxels, PCD and PLY."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from bagtools.cloud import MapCloud, PointAccumulator, voxel_average
from bagtools.commands.map_cloud import write_point_cloud
from bagtools.io import decode_pointcloud2
from tests.conftest import TYPESTORE, _header, make_tf, write_bag


def make_xyzir_cloud(stamp_ns: int, xyz: np.ndarray, intensity: np.ndarray, rgb: np.ndarray, frame_id: str = "lidar",
                     rgb_type: int = 7, intensity_type: int = 7, bigendian: bool = False):
    """A PointCloud2 with x y z (float32), intensity (float32 or uint16) and PCL's packed rgb (float32 or uint32)."""
    T = TYPESTORE.types
    order = ">" if bigendian else "<"
    i_kind = {7: "f4", 4: "u2"}[intensity_type]
    dtype = np.dtype({"names": ["x", "y", "z", "intensity", "rgb"],
                      "formats": [order + "f4"] * 3 + [order + i_kind, order + "u4"],
                      "offsets": [0, 4, 8, 16, 20], "itemsize": 32})
    rec = np.zeros(len(xyz), dtype=dtype)
    for k, name in enumerate("xyz"):
        rec[name] = xyz[:, k]
    rec["intensity"] = intensity
    c = np.asarray(rgb, dtype=np.uint32)
    rec["rgb"] = (c[:, 0] << 16) | (c[:, 1] << 8) | c[:, 2]
    PF = T["sensor_msgs/msg/PointField"]
    fields = [PF(name=n, offset=o, datatype=7, count=1) for n, o in zip("xyz", (0, 4, 8))]
    fields += [PF(name="intensity", offset=16, datatype=intensity_type, count=1),
               PF(name="rgb", offset=20, datatype=rgb_type, count=1)]
    return T["sensor_msgs/msg/PointCloud2"](
        header=_header(stamp_ns, frame_id), height=1, width=len(xyz), fields=fields, is_bigendian=bigendian,
        point_step=32, row_step=32 * len(xyz), data=rec.view(np.uint8).reshape(-1), is_dense=False)


XYZ = np.array([[1.0, 2.0, 3.0], [np.nan, 0.0, 0.0], [4.0, 5.0, 6.0], [7.0, 8.0, 9.0]])
INTENSITY = np.array([10.0, 99.0, 20.0, 30.0])
RGB = np.array([[255, 0, 0], [1, 1, 1], [0, 128, 0], [0, 0, 7]], dtype=np.uint8)


@pytest.mark.parametrize("rgb_type,intensity_type,bigendian", [(7, 7, False), (6, 4, False), (7, 7, True)])
def test_decode_keeps_intensity_and_colour_aligned_with_finite_points(rgb_type: int, intensity_type: int,
                                                                      bigendian: bool) -> None:
    msg = make_xyzir_cloud(5, XYZ, INTENSITY, RGB, rgb_type=rgb_type, intensity_type=intensity_type, bigendian=bigendian)
    cloud = decode_pointcloud2(msg, attributes=True)
    assert cloud.points.shape == (3, 3)
    assert cloud.intensity.dtype == np.float32 and cloud.intensity.tolist() == [10.0, 20.0, 30.0]
    assert cloud.rgb.dtype == np.uint8 and cloud.rgb.tolist() == [[255, 0, 0], [0, 128, 0], [0, 0, 7]]
    plain = decode_pointcloud2(msg)
    assert plain.intensity is None and plain.rgb is None and np.array_equal(plain.points, cloud.points)


def test_decode_separate_rgb_channels_and_no_attributes() -> None:
    T = TYPESTORE.types
    PF = T["sensor_msgs/msg/PointField"]
    dtype = np.dtype({"names": ["x", "y", "z", "r", "g", "b"], "formats": ["<f4"] * 3 + ["u1"] * 3,
                      "offsets": [0, 4, 8, 12, 13, 14], "itemsize": 16})
    rec = np.zeros(2, dtype=dtype)
    rec["x"] = [1, 2]
    rec["r"], rec["g"], rec["b"] = [10, 20], [30, 40], [50, 60]
    fields = [PF(name=n, offset=o, datatype=7, count=1) for n, o in zip("xyz", (0, 4, 8))]
    fields += [PF(name=c, offset=12 + k, datatype=2, count=1) for k, c in enumerate("rgb")]
    msg = T["sensor_msgs/msg/PointCloud2"](header=_header(1, "cam"), height=1, width=2, fields=fields, is_bigendian=False,
                                           point_step=16, row_step=32, data=rec.view(np.uint8).reshape(-1), is_dense=True)
    cloud = decode_pointcloud2(msg, attributes=True)
    assert cloud.rgb.tolist() == [[10, 30, 50], [20, 40, 60]] and cloud.intensity is None


def test_voxel_average_means_attributes_and_matches_open3d_voxels() -> None:
    import open3d as o3d

    rng = np.random.default_rng(3)
    points = rng.uniform(0, 1, size=(5000, 3)).astype(np.float32)
    intensity = rng.uniform(0, 100, size=5000).astype(np.float32)
    rgb = rng.integers(0, 256, size=(5000, 3)).astype(np.uint8)
    out = voxel_average(MapCloud(points, intensity, rgb), 0.25)
    ref = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points.astype(np.float64)))
    ref.colors = o3d.utility.Vector3dVector(rgb / 255.0)
    ref = ref.voxel_down_sample(0.25)
    order = np.lexsort(np.asarray(ref.points).T)
    mine = np.lexsort(out.points.T)
    assert len(out) == len(ref.points)
    assert np.allclose(out.points[mine], np.asarray(ref.points)[order], atol=1e-5)
    assert np.abs(out.rgb[mine].astype(int) - np.rint(np.asarray(ref.colors)[order] * 255)).max() <= 1
    # the intensity of each voxel is the mean of its points' intensities
    lo = points.min(axis=0) - 0.125
    cells = np.floor((points - lo) / 0.25).astype(int)
    first = tuple(cells[0])
    members = np.all(cells == first, axis=1)
    cell_of_out = np.floor((out.points - lo) / 0.25).astype(int)
    k = np.flatnonzero(np.all(cell_of_out == first, axis=1))[0]
    assert out.intensity[k] == pytest.approx(intensity[members].mean(), rel=1e-5)


def test_accumulator_drops_an_attribute_some_input_lacks() -> None:
    acc = PointAccumulator()
    acc.add(np.zeros((2, 3)), np.ones(2), np.zeros((2, 3), dtype=np.uint8))
    acc.add(np.ones((2, 3)), None, np.zeros((2, 3), dtype=np.uint8))
    cloud = acc.cloud()
    assert cloud.intensity is None and cloud.rgb is not None and acc.dropped == {"intensity"}


def test_files_hold_fields_and_frame(tmp_path: Path) -> None:
    import open3d as o3d

    cloud = MapCloud(np.arange(12, dtype=np.float32).reshape(4, 3), np.array([1, 2, 3, 4], dtype=np.float32),
                     np.array([[255, 0, 0], [0, 255, 0], [0, 0, 255], [9, 8, 7]], dtype=np.uint8))
    for name in ("m.pcd", "m.ply"):
        write_point_cloud(tmp_path / name, cloud, "odom")
        t = o3d.t.io.read_point_cloud(str(tmp_path / name))
        assert np.array_equal(t.point["positions"].numpy(), cloud.points)
        assert t.point["intensity"].numpy().ravel().tolist() == [1, 2, 3, 4]
        assert t.point["colors"].numpy().tolist() == cloud.rgb.tolist()
    assert b"# frame_id: odom\n" in (tmp_path / "m.pcd").read_bytes()[:200]
    assert b"comment frame_id: odom\n" in (tmp_path / "m.ply").read_bytes()[:200]
    write_point_cloud(tmp_path / "bare.pcd", cloud.points)
    assert np.asarray(o3d.io.read_point_cloud(str(tmp_path / "bare.pcd")).points).shape == (4, 3)


@pytest.fixture
def colour_bag(tmp_path: Path) -> Path:
    """5 clouds of x y z intensity rgb in 'lidar', 1 m above a robot standing still at x = 1 in map."""
    t0 = 1_700_000_000_000_000_000
    msgs = [("/tf_static", "tf2_msgs/msg/TFMessage", t0, make_tf(t0, "base_link", "lidar", (0, 0, 1.0), (0, 0, 0, 1)))]
    for i in range(30):
        t = t0 + i * 100_000_000
        msgs.append(("/tf", "tf2_msgs/msg/TFMessage", t, make_tf(t, "map", "base_link", (1.0, 0, 0), (0, 0, 0, 1))))
    rng = np.random.default_rng(0)
    for i in range(5):
        t = t0 + (5 + i) * 100_000_000
        # two tight clusters: one near (0,0,0) (dim, red), one near (2,0,0) (bright, blue) in the lidar frame
        a = rng.normal([0.05, 0.05, 0.05], 0.005, size=(20, 3))
        b = rng.normal([2.05, 0.05, 0.05], 0.005, size=(20, 3))
        xyz = np.vstack([a, b])
        intensity = np.r_[np.full(20, 10.0 + i), np.full(20, 200.0)]
        rgb = np.vstack([np.tile([200 + i, 0, 0], (20, 1)), np.tile([0, 0, 250], (20, 1))])
        msgs.append(("/points", "sensor_msgs/msg/PointCloud2", t + 1, make_xyzir_cloud(t, xyz, intensity, rgb)))
    msgs.sort(key=lambda m: m[2])
    return write_bag(tmp_path / "colour", msgs)


def test_map_cloud_keeps_intensity_and_colour_averaged_per_voxel(colour_bag: Path, tmp_path: Path) -> None:
    import open3d as o3d

    out = tmp_path / "map"
    result = subprocess.run([sys.executable, "-m", "bagtools", "map-cloud", str(colour_bag), "--out", str(out),
                             "--topic", "/points", "--sample", "1", "--voxel", "0.5", "--no-mcap"],
                            capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    t = o3d.t.io.read_point_cloud(str(out / "cloud_map.pcd"))
    positions, intensity, colors = (t.point[k].numpy() for k in ("positions", "intensity", "colors"))
    assert positions.shape == (2, 3)
    dim = np.argmin(positions[:, 0])
    assert positions[dim] == pytest.approx([1.05, 0.05, 1.05], abs=0.01)  # 1 m up, robot at x = 1
    assert intensity[dim, 0] == pytest.approx(12.0) and intensity[1 - dim, 0] == pytest.approx(200.0)
    assert colors[dim].tolist() == [202, 0, 0] and colors[1 - dim].tolist() == [0, 0, 250]
    ply = o3d.t.io.read_point_cloud(str(out / "cloud_map.ply"))
    assert np.allclose(np.sort(ply.point["intensity"].numpy().ravel()), [12.0, 200.0])
    legacy = o3d.io.read_point_cloud(str(out / "cloud_map.pcd"))
    assert np.asarray(legacy.colors).shape == (2, 3)
    assert b"# frame_id: map\n" in (out / "cloud_map.pcd").read_bytes()[:300]
    assert b"comment frame_id: map\n" in (out / "cloud_map.ply").read_bytes()[:300]


def test_pcd_reads_in_pypcd4(colour_bag: Path, tmp_path: Path) -> None:
    pypcd4 = pytest.importorskip("pypcd4")
    from bagtools.commands.map_cloud import CloudMapOptions, CloudMapPipeline, write_cloud_map

    result = CloudMapPipeline(colour_bag, CloudMapOptions(topic="/points", sample=1.0, voxel_m=0.5)).run()
    write_cloud_map(result, tmp_path / "m")
    pc = pypcd4.PointCloud.from_path(tmp_path / "m" / "cloud_map.pcd")
    assert pc.fields == ("x", "y", "z", "intensity", "rgb")
    rgb = pypcd4.PointCloud.decode_rgb(pc.numpy(("rgb",)).ravel())
    assert sorted(pc.numpy(("intensity",)).ravel().tolist()) == pytest.approx([12.0, 200.0])
    assert sorted(map(tuple, rgb.tolist())) == [(0, 0, 250), (202, 0, 0)]
