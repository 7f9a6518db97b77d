"""Shared test fixtures: paths to the real bags and small synthetic bags written with rosbags."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

REPO = Path(__file__).resolve().parents[1]
REAL_DIR = REPO.parent / "shared" / "data" / "real"
FIXTURES = REPO / "fixtures"
TYPESTORE = get_typestore(Stores.ROS2_HUMBLE)


@pytest.fixture
def real_dir() -> Path:
    """The folder of real ROS bags beside the checkout; skips when absent."""
    if not REAL_DIR.is_dir():
        pytest.skip(f"real bags not available: {REAL_DIR} does not exist (they live beside the checkout, in ../shared/data/real)")
    return REAL_DIR


def _header(stamp_ns: int, frame_id: str):
    T = TYPESTORE.types
    return T["std_msgs/msg/Header"](
        stamp=T["builtin_interfaces/msg/Time"](sec=stamp_ns // 1_000_000_000, nanosec=stamp_ns % 1_000_000_000),
        frame_id=frame_id,
    )


def make_scan(stamp_ns: int, ranges: np.ndarray, angle_min: float = 0.0, increment: float = np.pi / 180):
    T = TYPESTORE.types
    return T["sensor_msgs/msg/LaserScan"](
        header=_header(stamp_ns, "base_scan"), angle_min=angle_min,
        angle_max=angle_min + increment * (len(ranges) - 1), angle_increment=increment, time_increment=0.0,
        scan_time=0.2, range_min=0.12, range_max=3.5, ranges=np.asarray(ranges, dtype=np.float32),
        intensities=np.zeros(0, dtype=np.float32),
    )


def make_cloud(stamp_ns: int, xyz: np.ndarray, frame_id: str = "camera", point_step: int = 16, row_pad: int = 0,
               bigendian: bool = False, dtype: str = "f4", height: int = 1):
    """A PointCloud2 with x, y, z of numpy kind ``dtype`` at offsets 0, size, 2*size, padded to point_step."""
    T = TYPESTORE.types
    xyz = np.asarray(xyz, dtype=np.float64)
    n = xyz.shape[0]
    width = n // height
    size = np.dtype(dtype).itemsize
    order = ">" if bigendian else "<"
    rec = np.zeros(n, dtype=np.dtype({"names": list("xyz"), "formats": [order + dtype] * 3,
                                      "offsets": [0, size, 2 * size], "itemsize": point_step}))
    for i, name in enumerate("xyz"):
        rec[name] = xyz[:, i]
    rows = rec.view(np.uint8).reshape(height, width * point_step)
    data = np.concatenate([rows, np.full((height, row_pad), 0xEE, dtype=np.uint8)], axis=1).reshape(-1)
    datatype = {"f4": 7, "f8": 8}[dtype]
    fields = [T["sensor_msgs/msg/PointField"](name=nm, offset=i * size, datatype=datatype, count=1) for i, nm in enumerate("xyz")]
    return T["sensor_msgs/msg/PointCloud2"](
        header=_header(stamp_ns, frame_id), height=height, width=width, fields=fields, is_bigendian=bigendian,
        point_step=point_step, row_step=width * point_step + row_pad, data=data, is_dense=False,
    )


def make_tf(stamp_ns: int, parent: str, child: str, xyz, quat_xyzw):
    T = TYPESTORE.types
    ts = T["geometry_msgs/msg/TransformStamped"](
        header=_header(stamp_ns, parent), child_frame_id=child,
        transform=T["geometry_msgs/msg/Transform"](
            translation=T["geometry_msgs/msg/Vector3"](x=xyz[0], y=xyz[1], z=xyz[2]),
            rotation=T["geometry_msgs/msg/Quaternion"](x=quat_xyzw[0], y=quat_xyzw[1], z=quat_xyzw[2], w=quat_xyzw[3]),
        ),
    )
    return T["tf2_msgs/msg/TFMessage"](transforms=[ts])


def write_bag(path: Path, messages: list[tuple[str, str, int, object]], storage: str = "mcap") -> Path:
    """Write (topic, msgtype, log_time_ns, msg) tuples as a rosbag2 directory; return the path."""
    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    writer = Writer(path, version=9, storage_plugin=plugin)
    if storage == "mcap":
        writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
    with writer:
        conns = {}
        for topic, msgtype, t_ns, msg in messages:
            if topic not in conns:
                conns[topic] = writer.add_connection(topic, msgtype, typestore=TYPESTORE)
            writer.write(conns[topic], t_ns, TYPESTORE.serialize_cdr(msg, msgtype))
    return path


@pytest.fixture
def synthetic_bag(tmp_path: Path) -> Path:
    """A 10 s rosbag2 MCAP directory: /tf at 10 Hz, /tf_static, /scan at 5 Hz, /cloud at 1 Hz."""
    t0 = 1_700_000_000_000_000_000
    msgs: list[tuple[str, str, int, object]] = [
        ("/tf_static", "tf2_msgs/msg/TFMessage", t0, make_tf(t0, "base_link", "base_scan", (-0.064, 0, 0.121), (0, 0, 0, 1)))
    ]
    for i in range(100):
        t = t0 + i * 100_000_000
        msgs.append(("/tf", "tf2_msgs/msg/TFMessage", t + 2_000_000, make_tf(t, "odom", "base_link", (0.1 * i, 0, 0), (0, 0, 0, 1))))
        if i % 2 == 0:
            ranges = np.full(360, 2.0, dtype=np.float32)
            ranges[::10] = np.inf
            msgs.append(("/scan", "sensor_msgs/msg/LaserScan", t + 20_000_000, make_scan(t, ranges)))
        if i % 10 == 0:
            xyz = np.array([[1.0, 2.0, 3.0], [np.nan, np.nan, np.nan], [4.0, 5.0, 6.0], [7.0, 8.0, 9.0]])
            msgs.append(("/cloud", "sensor_msgs/msg/PointCloud2", t + 40_000_000, make_cloud(t, xyz)))
    msgs.sort(key=lambda m: m[2])
    return write_bag(tmp_path / "synthetic", msgs)


def ros1_scan_slice(source: Path, path: Path, first: int, last: int, scan_topic: str = "/scan") -> Path:
    """A ROS 1 bag of scans ``first``..``last - 1`` (0-based, in the order recorded) of the ROS 1 bag ``source``,
    with every other topic's messages from the scan before the first on, and /tf_static whenever recorded."""
    from rosbags.rosbag1 import Reader as Ros1Reader
    from rosbags.rosbag1 import Writer as Ros1Writer

    with Ros1Reader(source) as reader, Ros1Writer(path) as writer:
        out = {c.id: writer.add_connection(c.topic, c.msgtype, msgdef=c.msgdef.data, md5sum=c.digest)
               for c in reader.connections}
        seen = 0  # scans before this message
        for conn, t_ns, raw in reader.messages():
            if conn.topic == scan_topic:
                if seen >= last:
                    break
                if seen >= first:
                    writer.write(out[conn.id], t_ns, raw)
                seen += 1
            elif seen >= first or conn.topic == "/tf_static":
                writer.write(out[conn.id], t_ns, raw)
    return path


# -- SLAM and pose-graph fixtures: a long simulated figure eight, and the real CSAIL log ---------------------------


@pytest.fixture(scope="session")
def figure8_bag(tmp_path_factory) -> Path:
    """A 200 s figure eight with high wheel-odometry noise, no camera (about 1000 scans, 35 m)."""
    from bagtools_simulate.pipeline import SimConfig, simulate_bag
    path = tmp_path_factory.mktemp("slam_sim") / "figure8"
    simulate_bag(path, SimConfig(duration_s=200.0, route="figure8", odom_noise="high", cloud=False, seed=3))
    return path


@pytest.fixture(scope="session")
def figure8_front(figure8_bag: Path):
    """The stand-in front end (tests/standin.py) of the figure eight: its ground truth with SIM_DRIFT."""
    from tests.standin import SIM_DRIFT, front_end_from_truth
    return front_end_from_truth(figure8_bag, drift=SIM_DRIFT)


@pytest.fixture(scope="session")
def csail_odom() -> Path:
    path = REAL_DIR / "csail_odom"
    if not path.is_dir():
        pytest.skip(f"real bags not available: {path} does not exist")
    return path


@pytest.fixture(scope="session")
def csail_scans_run():
    """The scans-only CSAIL log through the laser odometry (``run_front_end``, no odometry): once per session for
    the front end's and slam's tests."""
    from bagtools.odometry.options import NdtOdomOptions
    from bagtools.odometry.pipeline import run_front_end
    bag = REAL_DIR / "csail_scans"
    if not bag.is_dir():
        pytest.skip(f"real bags not available: {bag} does not exist")
    return run_front_end(bag, NdtOdomOptions(use_odometry=False))


@pytest.fixture(scope="session")
def csail_restarted(csail_scans_run):
    """``restarted(first)``: the laser odometry of the CSAIL scans from scan ``first`` on (a FrontEndRun), each start
    run once per session: other speeds and keyframes at the sharp turns of scans 52-66."""
    from functools import lru_cache

    from bagtools.odometry import LaserOdometry
    from bagtools.odometry.options import cell_size_for
    from bagtools.odometry.options import NdtOdomOptions

    steps = csail_scans_run.front_end.steps
    options = NdtOdomOptions(use_odometry=False).front_end(cell_size_for([s.points_base for s in steps]))

    @lru_cache(maxsize=None)
    def restarted(first: int):
        front = LaserOdometry(options)
        for step in steps[first:]:
            front.register(step.stamp_ns, step.points_base, None)
        return front.run

    return restarted
