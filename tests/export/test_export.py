"""`bagtools export`: tables pandas reads back with the bag's values; one-line errors for what cannot be exported."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from bagtools.errors import BagtoolsError
from bagtools.commands.export import export_topic
from bagtools.io import decode_laserscan, decode_odometry, decode_pointcloud2, decode_tf_message, open_bag
from tests.map_cloud.test_attributes import INTENSITY, RGB, XYZ, make_xyzir_cloud
from tests.conftest import TYPESTORE, _header, make_scan, write_bag

FIXTURE = Path(__file__).resolve().parents[2] / "fixtures" / "sim_lap_cloud_20s"


def run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "bagtools", "export", *args], capture_output=True, text=True, timeout=300)


def _records(topic: str) -> list:
    with open_bag(FIXTURE) as bag:
        return list(bag.messages([topic]))


def test_odometry_csv_has_flat_columns_and_exact_stamps(tmp_path: Path) -> None:
    summary = export_topic(FIXTURE, "/odom", tmp_path / "odom.csv")
    df = pd.read_csv(tmp_path / "odom.csv")
    recs = _records("/odom")
    assert summary.rows == len(df) == len(recs) == 601
    assert list(df.columns[:17]) == ["stamp_ns", "log_time_ns", "frame_id", "child_frame_id", "x", "y", "z", "qx", "qy",
                                     "qz", "qw", "vx", "vy", "vz", "wx", "wy", "wz"]
    assert df["stamp_ns"].dtype == np.int64 and df["log_time_ns"].tolist() == [r.log_time_ns for r in recs]
    odom = decode_odometry(recs[300].msg)
    assert df["stamp_ns"][300] == odom.stamp_ns and df["child_frame_id"][300] == odom.child_frame_id
    assert df.loc[300, ["x", "y", "qz", "qw", "vx", "wz"]].tolist() == pytest.approx(
        [*odom.position_m[:2], *odom.orientation_xyzw[2:], odom.linear_mps[0], odom.angular_radps[2]], abs=0, rel=1e-15)
    assert df[[f"pose_covariance.{i}" for i in range(36)]].iloc[300].to_numpy() == pytest.approx(
        odom.pose_covariance.ravel())


def test_scans_parquet_lists_and_csv_beams(tmp_path: Path) -> None:
    export_topic(FIXTURE, "/scan", tmp_path / "scan.parquet")
    export_topic(FIXTURE, "/scan", tmp_path / "scan.csv")
    df = pd.read_parquet(tmp_path / "scan.parquet")
    scan = decode_laserscan(_records("/scan")[7].msg)
    assert len(df) == 101 and df["stamp_ns"][7] == scan.stamp_ns and df["frame_id"][7] == scan.frame_id
    assert np.array_equal(np.asarray(df["ranges"][7]), scan.ranges_m, equal_nan=True)
    wide = pd.read_csv(tmp_path / "scan.csv")
    beams = wide[[f"ranges.{i}" for i in range(scan.ranges_m.size)]].iloc[7].to_numpy(dtype=np.float32)
    assert np.array_equal(beams, scan.ranges_m, equal_nan=True)  # float32 written in shortest form, read back exactly


def test_tf_one_row_per_transform_and_points_per_point(tmp_path: Path) -> None:
    export_topic(FIXTURE, "/tf", tmp_path / "tf.npz")
    with np.load(tmp_path / "tf.npz") as npz:  # no pickle needed
        tf = [decode_tf_message(r.msg) for r in _records("/tf")]
        assert npz["x"].size == sum(len(t) for t in tf)
        parents = np.concatenate([t.parent for t in tf])  # stored once each: rows index NAME.values
        assert npz["frame_id.values"].size < 5 and npz["frame_id"].dtype == np.int16
        assert (npz["frame_id.values"][npz["frame_id"]] == parents).all()
        assert npz["child_frame_id.values"][npz["child_frame_id"]][0] == tf[0].child[0]
        assert npz["stamp_ns"].dtype == np.int64 and npz["stamp_ns"][0] == tf[0].stamp_ns[0]
    summary = export_topic(FIXTURE, "/camera/depth/points", tmp_path / "pts.parquet", keep_nan=True)
    df = pd.read_parquet(tmp_path / "pts.parquet")
    msgs = _records("/camera/depth/points")
    assert summary.rows == len(df) == sum(m.msg.width * m.msg.height for m in msgs)  # every point, as recorded
    finite = export_topic(FIXTURE, "/camera/depth/points", tmp_path / "finite.parquet")
    assert finite.rows == sum(decode_pointcloud2(m.msg).points.shape[0] for m in msgs) < summary.rows
    assert list(df.columns) == ["stamp_ns", "log_time_ns", "frame_id", "x", "y", "z"]


def test_cloud_attributes_and_ragged_scans(tmp_path: Path) -> None:
    t0 = 1_700_000_000_000_000_000
    bag = write_bag(tmp_path / "bag", [
        ("/points", "sensor_msgs/msg/PointCloud2", t0, make_xyzir_cloud(t0, XYZ, INTENSITY, RGB)),
        ("/scan", "sensor_msgs/msg/LaserScan", t0, make_scan(t0, np.ones(4))),
        ("/scan", "sensor_msgs/msg/LaserScan", t0 + 1, make_scan(t0 + 1, np.ones(6))),
    ])
    export_topic(bag, "/points", tmp_path / "p.csv")
    df = pd.read_csv(tmp_path / "p.csv")
    assert list(df.columns) == ["stamp_ns", "log_time_ns", "frame_id", "x", "y", "z", "intensity", "r", "g", "b"]
    finite = np.isfinite(XYZ).all(axis=1)  # the point with a NaN coordinate is dropped, with its attributes
    assert df["intensity"].tolist() == INTENSITY[finite].tolist()
    assert df[["r", "g", "b"]].to_numpy().tolist() == RGB[finite].tolist()
    assert np.isfinite(df[["x", "y", "z"]].to_numpy()).all() and len(df) == finite.sum()
    kept = pd.read_csv(export_topic(bag, "/points", tmp_path / "all.csv", keep_nan=True).path)
    assert len(kept) == len(XYZ) and np.isnan(kept["x"][1])  # every point, as recorded
    export_topic(bag, "/scan", tmp_path / "s.npz")
    with np.load(tmp_path / "s.npz") as npz:
        assert npz["ranges"].shape == (2, 6) and np.isnan(npz["ranges"][0, 4:]).all()
    assert [len(r) for r in pd.read_parquet(export_topic(bag, "/scan", tmp_path / "s.parquet").path)["ranges"]] == [4, 6]
    with pytest.raises(BagtoolsError, match="export to .parquet or .npz"):
        export_topic(bag, "/scan", tmp_path / "s.csv")
    assert not (tmp_path / "s.csv").exists()


def test_help_has_an_example() -> None:
    done = run("--help")
    assert done.returncode == 0 and "Example:" in done.stdout and "bagtools export out/sim /odom --out odom.csv" in done.stdout


@pytest.mark.parametrize("args,problem", [
    (lambda d: [str(FIXTURE), "/nope", "--out", str(d / "o.csv")], "no topic '/nope' in the bag"),
    (lambda d: [str(FIXTURE), "/odom", "--out", str(d / "o.xlsx")], "unknown output format '.xlsx'"),
    (lambda d: [str(d / "missing"), "/odom", "--out", str(d / "o.csv")], "no such file or directory"),
    (lambda d: [str(FIXTURE), "/odom", "--out", str((d / "old.csv").touch() or d / "old.csv")], "already exists"),
])
def test_bad_input_one_line_exit_2(tmp_path: Path, args, problem: str) -> None:
    done = run(*args(tmp_path))
    assert done.returncode == 2, done.stderr
    assert done.stderr.count("\n") == 1 and "Traceback" not in done.stderr and problem in done.stderr
    assert {p.name for p in tmp_path.iterdir()} <= {"old.csv"}


def test_any_message_type_is_flattened_from_its_definition(tmp_path: Path) -> None:
    """/imu and /joint_states of the simulated bag, a CompressedImage and a header-less std_msgs/String."""
    imu = pd.read_parquet(export_topic(FIXTURE, "/imu", tmp_path / "imu.parquet").path)
    first = _records("/imu")[0].msg
    assert len(imu) == 4001 and imu["frame_id"][0] == first.header.frame_id
    assert imu["linear_acceleration.z"][0] == first.linear_acceleration.z
    assert imu["orientation.w"][0] == first.orientation.w
    assert list(imu["orientation_covariance"][0]) == list(first.orientation_covariance)
    joints = pd.read_csv(export_topic(FIXTURE, "/joint_states", tmp_path / "j.csv").path)
    names = json.loads(joints["name"][0])
    assert names == list(_records("/joint_states")[0].msg.name) and "position.0" in joints.columns
    world = pd.read_parquet(export_topic(FIXTURE, "/simulation/world", tmp_path / "w.parquet").path)
    record = _records("/simulation/world")[0]
    assert world["data"][0] == record.msg.data and world["stamp_ns"][0] == record.log_time_ns  # no header: bag time
    t0 = 1_700_000_000_000_000_000
    image = TYPESTORE.types["sensor_msgs/msg/CompressedImage"](header=_header(t0, "camera"), format="jpeg",
                                                               data=np.arange(1000, dtype=np.uint8))
    bag = write_bag(tmp_path / "img", [("/image/compressed", "sensor_msgs/msg/CompressedImage", t0, image)])
    with np.load(export_topic(bag, "/image/compressed", tmp_path / "img.npz").path) as npz:
        assert npz["data.bytes"].tolist() == [1000] and npz["format"][0] == "jpeg"  # one row: nothing repeats
