"""Repairs of recorded tf data: corrupt samples, glitches, repeated stamps, interleaved publishers."""

from __future__ import annotations

import numpy as np
import pytest

from bagtools.io import TfArrays
from bagtools.tf import InvalidArgumentException
from bagtools.tf.repair import inspect_edge, repair_dynamic_tf, tf_conflicts, translation_spike_mask

T0 = 1_700_000_000_000_000_000
S = 1_000_000_000


def test_corrupt_leaps_dropped_and_steps_kept() -> None:
    n = 50
    stamps = T0 + np.arange(n, dtype=np.int64) * S // 10
    xyz = np.column_stack([np.arange(n) * 0.02, np.zeros(n), np.zeros(n)])
    xyz[30:, 1] += 0.5                     # a localizer step: kept
    xyz[10, 1] = 1.9e32                    # a corrupt sample: dropped
    xyz[20:22, 0] = 5.9e22                 # two in a row: dropped
    q = np.tile([0.0, 0.0, 0.0, 1.0], (n, 1))
    arrays = TfArrays(np.array(["odom"] * n, dtype=object), np.array(["base_link"] * n, dtype=object), stamps, xyz, q)
    keep, dropped = translation_spike_mask(arrays)
    assert dropped == {("odom", "base_link"): 3}
    warnings: list[str] = []
    kept, keep_again = repair_dynamic_tf(arrays, warnings)
    assert np.array_equal(keep, keep_again)
    assert warnings == ["dropped 3 corrupt /tf samples odom -> base_link (translation leaping away from its neighbours and back)"]
    assert len(kept) == n - 3 and np.abs(kept.translation).max() < 2.0
    assert set(kept.stamp_ns) == set(stamps) - {stamps[10], stamps[20], stamps[21]}


def test_from_bag_repairs_corrupt_odometry_of_a_real_bag(real_dir) -> None:
    from bagtools.tf import TfBuffer

    buffer = TfBuffer.from_bag(real_dir / "turtlebot3_real_lidar_odom.bag")
    assert any("dropped 8 corrupt /tf samples odom -> base_link" in w for w in buffer.warnings)
    first, last = buffer.time_range("odom", "base_link")
    stamps = first + (np.arange(2000, dtype=np.int64) * (last - first)) // 1999
    T = buffer.lookup("odom", "base_link", stamps)
    assert np.abs(T[:, :3, 3]).max() < 5.0  # the robot stays in its small arena


def test_from_arrays_repairs_only_when_asked() -> None:
    from bagtools.tf import TfBuffer

    n = 20
    xyz = np.column_stack([np.arange(n) * 0.02, np.zeros(n), np.zeros(n)])
    xyz[7, 0] = 1e6   # a leap the buffer takes (1e30 m it refuses as invalid, repaired or not: below)
    arrays = TfArrays(np.array(["odom"] * n, dtype=object), np.array(["base"] * n, dtype=object),
                      T0 + np.arange(n, dtype=np.int64) * S // 10, xyz, np.tile([0.0, 0.0, 0.0, 1.0], (n, 1)))
    raw = TfBuffer.from_arrays(arrays)
    assert raw.lookup("odom", "base", int(arrays.stamp_ns[7]))[0, 3] == 1e6
    repaired = TfBuffer.from_arrays(arrays, repair_spikes=True)
    assert abs(repaired.lookup("odom", "base", int(arrays.stamp_ns[7]))[0, 3] - 0.14) < 1e-9
    assert repaired.warnings == ["dropped 1 corrupt /tf samples odom -> base (translation leaping away from its neighbours and back)"]
    arrays.translation[7, 0] = 1e30
    with pytest.raises(InvalidArgumentException, match="translation beyond 1e\\+09 m"):
        TfBuffer.from_arrays(arrays)
    assert TfBuffer.from_arrays(arrays, repair_spikes=True).warnings == repaired.warnings


def edge(xyz: np.ndarray, yaw: np.ndarray | None = None, stamps: np.ndarray | None = None,
         parent: str = "odom", child: str = "base_link") -> TfArrays:
    n = len(xyz)
    yaw = np.zeros(n) if yaw is None else yaw
    q = np.column_stack([np.zeros(n), np.zeros(n), np.sin(yaw / 2), np.cos(yaw / 2)])
    stamps = T0 + np.arange(n, dtype=np.int64) * S // 20 if stamps is None else stamps
    return TfArrays(np.array([parent] * n, dtype=object), np.array([child] * n, dtype=object), stamps,
                    np.asarray(xyz, dtype=float), q)


def driving(n: int = 200) -> tuple[np.ndarray, np.ndarray]:
    t = np.arange(n) / 20.0
    xyz = np.column_stack([3.0 + 0.2 * t, 1.0 + 0.05 * np.sin(t), np.zeros(n)])
    return xyz, 0.1 * t


def test_glitches_zeroed_coordinates_and_flipped_yaw_are_dropped() -> None:
    xyz, yaw = driving()
    xyz[50, 0] = 0.0                 # one coordinate zeroed
    xyz[90:92, 1] = 0.0              # two in a row
    yaw[130] += np.radians(170)      # a yaw flipped for one sample
    warnings: list[str] = []
    kept, keep = repair_dynamic_tf(edge(xyz, yaw), warnings)
    assert np.flatnonzero(~keep).tolist() == [50, 90, 91, 130]
    assert warnings == ["/tf odom -> base_link: dropped 4 isolated glitch(es) (samples far from those around them, "
                        "which agree: a zeroed coordinate or a flipped yaw)"]


def test_localizer_corrections_are_not_glitches() -> None:
    rng = np.random.default_rng(0)
    n = 300
    holds = np.repeat(rng.normal(0, 0.05, size=(n // 3, 3)), 3, axis=0)  # a pose held, corrected every 3 samples
    holds[:, 2] = 0
    found = inspect_edge(T0 + np.arange(n, dtype=np.int64) * S // 5, holds + [-2.0, -0.5, 0.0],
                         np.tile([0.0, 0.0, 0.0, 1.0], (n, 1)))
    assert found.drop.size == 0


def test_repeated_stamps_keep_the_first_and_conflicts_are_said() -> None:
    xyz, yaw = driving(40)
    stamps = T0 + np.arange(40, dtype=np.int64) * S // 20
    stamps[11] = stamps[10]                    # the same value twice: repeated data
    xyz[11] = xyz[10]
    yaw[11] = yaw[10]
    stamps[21], xyz[21] = stamps[20], xyz[20] + [0.4, 0, 0]   # another value at the same stamp: a conflict
    warnings: list[str] = []
    kept, keep = repair_dynamic_tf(edge(xyz, yaw, stamps), warnings)
    assert np.flatnonzero(~keep).tolist() == [11, 21]
    assert any("1 stamp(s) published twice with different values" in w for w in warnings)
    assert any("published twice" in w for w in tf_conflicts(edge(xyz, yaw, stamps), TfArrays.empty()))


def test_two_interleaved_publishers_keep_the_one_that_moves() -> None:
    moving, yaw = driving(100)                                     # 20 Hz, driving
    stamps_moving = T0 + np.arange(100, dtype=np.int64) * S // 20
    stamps_zero = T0 + 1 + np.arange(1000, dtype=np.int64) * S // 200   # 200 Hz, near zero
    zero = np.random.default_rng(1).normal(0, 1e-3, size=(1000, 3))
    both = TfArrays.concatenate([edge(moving, yaw, stamps_moving), edge(zero, np.zeros(1000), stamps_zero)])
    warnings: list[str] = []
    kept, keep = repair_dynamic_tf(both, warnings)
    assert keep[:100].sum() >= 95 and keep[100:].sum() == 0
    assert len(warnings) == 1 and "two publishers interleaved: kept" in warnings[0] and "20.0 Hz" in warnings[0]


def test_alternating_publishers_detected() -> None:
    a, yaw = driving(100)
    b = a.copy()
    b[:, 0] += 2.0
    xyz = np.empty((200, 3))
    xyz[0::2], xyz[1::2] = a, b
    found = inspect_edge(T0 + np.arange(200, dtype=np.int64) * S // 40, xyz, np.tile([0.0, 0.0, 0.0, 1.0], (200, 1)))
    assert "two publishers interleaved" in found.interleaved and found.drop.size == 100


def test_two_parents_reported() -> None:
    xyz, yaw = driving(10)
    both = TfArrays.concatenate([edge(xyz, yaw, parent="odom"), edge(xyz, yaw, parent="odom_alt")])
    assert any("frame base_link has 2 parents (odom on /tf, odom_alt on /tf)" in w
               for w in tf_conflicts(both, TfArrays.empty()))


def test_real_turtlebot_glitches_found(real_dir) -> None:
    from bagtools.io import open_bag, read_tf_arrays

    with open_bag(real_dir / "turtlebot3_real_lidar_odom.bag") as bag:
        dynamic, static = read_tf_arrays(bag)
    report = tf_conflicts(dynamic, static)
    assert any("8 corrupt" in w for w in report) and any("isolated glitch" in w for w in report)
    with open_bag(real_dir / "nav2_turtlebot.mcap") as bag:  # AMCL corrections are not glitches
        assert tf_conflicts(*read_tf_arrays(bag)) == []


def test_stray_stamp_dropped() -> None:
    xyz, yaw = driving(60)
    stamps = T0 + np.arange(60, dtype=np.int64) * S // 20
    stamps[0] = 1  # an unset clock
    warnings: list[str] = []
    kept, keep = repair_dynamic_tf(edge(xyz, yaw, stamps), warnings)
    assert np.flatnonzero(~keep).tolist() == [0]
    assert warnings == ["/tf odom -> base_link: dropped 1 sample(s) stamped far from all the others (an unset clock?)"]


def test_a_static_edge_given_two_values_is_said_wherever_tf_is_read(tmp_path) -> None:
    """Two /tf_static messages mount the camera 2.89 m apart: map-cloud's points move by that much, so the buffer,
    info and tf frames say so, and which value is used (the one set last, as tf2)."""
    from bagtools.tf import TfBuffer
    from bagtools.tf.repair import tf_conflicts
    from tests.conftest import make_tf, write_bag

    t0 = 1_700_000_000_000_000_000
    msgs = [("/tf_static", "tf2_msgs/msg/TFMessage", t0, make_tf(t0, "base_link", "camera", (0.1, 0, 0.3), (0, 0, 0, 1))),
            ("/tf_static", "tf2_msgs/msg/TFMessage", t0 + 1, make_tf(t0, "base_link", "camera", (2.99, 0, 0.3),
                                                                     (0, 0, 0, 1))),
            ("/tf_static", "tf2_msgs/msg/TFMessage", t0 + 2, make_tf(t0, "base_link", "laser", (0.2, 0, 0.1),
                                                                     (0, 0, 0, 1))),
            ("/tf_static", "tf2_msgs/msg/TFMessage", t0 + 3, make_tf(t0, "base_link", "laser", (0.2, 0, 0.1),
                                                                     (0, 0, 0, 1)))]
    bag = write_bag(tmp_path / "two_mounts", msgs)
    buffer = TfBuffer.from_bag(bag)
    said = [w for w in buffer.warnings if "/tf_static gives" in w]
    assert len(said) == 1 and "base_link -> camera 2 different values (up to 2.89 m" in said[0], buffer.warnings
    assert "used (2.99, 0, 0.3 m)" in said[0]
    np.testing.assert_allclose(buffer.lookup("base_link", "camera")[:3, 3], [2.99, 0, 0.3])
    from bagtools.io import open_bag, read_tf_arrays

    with open_bag(bag) as reader:
        dynamic, static = read_tf_arrays(reader)
    assert sum("/tf_static gives" in w for w in tf_conflicts(dynamic, static)) == 1


def test_a_jump_that_stays_is_said_not_repaired() -> None:
    """odom -> base_link jumps 1 km and stays (grid's precision fell to 0.165 after 140 s and 2.8 GB, silently):
    nothing tells which side is right, so it is said wherever tf is read, and nothing is dropped."""
    n = 100
    stamps = 1_700_000_000_000_000_000 + np.arange(n, dtype=np.int64) * 100_000_000
    t = np.zeros((n, 3))
    t[:, 0] = 0.05 * np.arange(n)
    t[60:, 0] += 1000.0
    q = np.tile([0.0, 0.0, 0.0, 1.0], (n, 1))
    found = inspect_edge(stamps, t, q)
    assert found.jumps == 1 and found.drop.size == 0 and abs(found.largest_jump_m - 1000.05) < 1e-6
    arrays = TfArrays(np.full(n, "odom", dtype=object), np.full(n, "base_link", dtype=object), stamps, t, q)
    said = tf_conflicts(arrays, TfArrays.empty())
    assert any("/tf odom -> base_link: jumps 1 time(s), up to 1e+03 m at once" in w for w in said), said
    smooth = inspect_edge(stamps, np.c_[0.05 * np.arange(n), np.zeros((n, 2))], q)
    assert smooth.jumps == 0


def test_two_nodes_on_one_edge_are_told_apart_by_their_callerids(tmp_path, capsys) -> None:
    """A real bag has odom -> base_link from wheel odometry (50 Hz) and a SLAM node (100 Hz) 1.7 m apart: no
    zig-zag a path test sees, but the ROS 1 connections name each publisher. info says so and which stream the
    mapping commands use; a buffer read through the repair keeps that one."""
    import pytest
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore

    from bagtools.cli import main
    from bagtools.io import open_bag, read_tf_arrays
    from bagtools.tf import TfBuffer

    from rosbags.typesys import get_types_from_msg

    ros1 = get_typestore(Stores.ROS1_NOETIC)
    ros1.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms", "tf2_msgs/msg/TFMessage"))
    T = ros1.types

    def tf(stamp_ns: int, x: float, y: float):
        header = T["std_msgs/msg/Header"](seq=0, stamp=T["builtin_interfaces/msg/Time"](
            sec=stamp_ns // 1_000_000_000, nanosec=stamp_ns % 1_000_000_000), frame_id="odom")
        ts = T["geometry_msgs/msg/TransformStamped"](header=header, child_frame_id="base_link", transform=T[
            "geometry_msgs/msg/Transform"](translation=T["geometry_msgs/msg/Vector3"](x=x, y=y, z=0.0),
                                           rotation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0)))
        return ros1.serialize_ros1(T["tf2_msgs/msg/TFMessage"](transforms=[ts]), "tf2_msgs/msg/TFMessage")

    t0 = 1_700_000_000_000_000_000
    bag = tmp_path / "two_nodes.bag"
    with Writer(bag) as writer:
        wheels = writer.add_connection("/tf", "tf2_msgs/msg/TFMessage", typestore=ros1, callerid="/wheel_odometry")
        slam = writer.add_connection("/tf", "tf2_msgs/msg/TFMessage", typestore=ros1, callerid="/slam_node")
        messages = [(t0 + i * 20_000_000, wheels, 0.01 * i, 0.0) for i in range(500)]
        messages += [(t0 + 5_000_000 + i * 10_000_000, slam, 0.005 * i, 1.7) for i in range(1000)]
        for stamp, conn, x, y in sorted(messages, key=lambda m: m[0]):
            writer.write(conn, stamp, tf(stamp, x, y))
    with open_bag(bag) as reader:
        dynamic, _ = read_tf_arrays(reader)
    assert set(dynamic.publisher) == {"/wheel_odometry", "/slam_node"}
    said = [w for w in tf_conflicts(dynamic, TfArrays.empty()) if "two publishers interleaved" in w]
    assert len(said) == 1 and "(/wheel_odometry and /slam_node, by the bag's callerids)" in said[0], said
    assert "the mapping commands use 1000 samples of /slam_node" in said[0]
    assert ", not 500 of /wheel_odometry" in said[0] and "the two are 1.7 m apart" in said[0]
    with pytest.raises(SystemExit):
        main(["info", str(bag)])
    assert "two publishers interleaved" in capsys.readouterr().err
    warnings: list[str] = []
    repaired, _ = repair_dynamic_tf(dynamic, warnings)
    assert any("kept 1000 samples of /slam_node" in w for w in warnings), warnings
    assert set(repaired.publisher) == {"/slam_node"}
    assert TfBuffer.from_bag(bag).lookup("odom", "base_link", t0 + 2_000_000_000)[1, 3] == pytest.approx(1.7)
