"""Property tests over the decoders, the tf buffer and the TUM reader, with arbitrary field values.

The contract (bagtools/errors.py): anything a user's data can cause is a
:class:`~bagtools.errors.BagtoolsError` (the CLI prints it as one line), so for
any input these functions either return results of consistent shape and finite
values, or raise a BagtoolsError subclass, never another exception; and a
decoder allocates no more than its message's data implies.

Messages are built with the rosbags typestore (as tests/conftest.py does) and
round-tripped through CDR, so that every field has the type and width a real
bag gives it (float32 angles, uint32 sizes, int32 seconds).
"""

from __future__ import annotations

import math
import os
import tempfile
import tracemalloc
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st

from bagtools.errors import BagtoolsError
from bagtools.io import decode_laserscan, decode_odometry, decode_pointcloud2, decode_tf_message
from bagtools.io.decode import TfArrays
from bagtools.tf import TfBuffer, TransformException
from bagtools.trajectory.tum import read_tum
from tests.conftest import TYPESTORE

T = TYPESTORE.types
# Deterministic (set HYPOTHESIS_RANDOM=1 for fresh examples) and without the shrink phase, so that the file
# takes ~20 s even while many properties fail; set BAGTOOLS_HYPOTHESIS_SHRINK=1 for minimal failing examples.
SETTINGS = dict(deadline=None, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
                derandomize=os.environ.get("HYPOTHESIS_RANDOM") is None,
                phases=[Phase.explicit, Phase.reuse, Phase.generate, Phase.target]
                + ([Phase.shrink] if os.environ.get("BAGTOOLS_HYPOTHESIS_SHRINK") else []))

# Values that real bags carry, and the ones damage or bugs produce.
SPECIAL = [0.0, -0.0, 1e-30, -1e-30, 1e30, -1e30, 3.4e38, -3.4e38, math.inf, -math.inf, math.nan, 1e-45]
any_float = st.one_of(st.sampled_from(SPECIAL), st.floats(allow_nan=True, allow_infinity=True, width=64),
                      st.floats(-100, 100))
float32s = st.one_of(st.sampled_from(SPECIAL), st.floats(allow_nan=True, allow_infinity=True, width=32),
                     st.floats(-100, 100, width=32))
uint32 = st.one_of(st.sampled_from([0, 1, 2, 3, 4, 8, 12, 16, 32, 255, 65535, 2**31 - 1, 2**31, 2**32 - 1]),
                   st.integers(0, 2**32 - 1))
stamp_sec = st.one_of(st.sampled_from([0, 1, 1_700_000_000, -1, 2**31 - 1, -(2**31)]), st.integers(-(2**31), 2**31 - 1))
stamp_nanosec = st.one_of(st.sampled_from([0, 1, 999_999_999, 10**9, 2**32 - 1]), st.integers(0, 2**32 - 1))
frame_ids = st.one_of(st.sampled_from(["", "/", "map", "odom", "base_link", "/base_link", " ", "a/b", "ü"]),
                      st.text(max_size=12))


def _roundtrip(msg, msgtype: str):
    """The message as a bag gives it: serialized to CDR and read back (fields get their ROS types)."""
    return TYPESTORE.deserialize_cdr(TYPESTORE.serialize_cdr(msg, msgtype), msgtype)


@st.composite
def headers(draw):
    return T["std_msgs/msg/Header"](
        stamp=T["builtin_interfaces/msg/Time"](sec=draw(stamp_sec), nanosec=draw(stamp_nanosec)),
        frame_id=draw(frame_ids))


def _call_measured(fn, *args):
    """(result or the exception raised, peak bytes allocated by Python and numpy)."""
    tracemalloc.start()
    try:
        try:
            result = fn(*args)
        except Exception as exc:  # noqa: BLE001 - classified by the caller
            result = exc
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    return result, peak


def _no_foreign_exception(result) -> None:
    if isinstance(result, Exception) and not isinstance(result, BagtoolsError):
        raise AssertionError(f"raised {type(result).__module__}.{type(result).__name__}: {result}") from result


# ---------------------------------------------------------------------------- LaserScan


@st.composite
def laserscans(draw):
    n = draw(st.integers(0, 400))
    ranges = draw(st.one_of(
        st.lists(float32s, min_size=n, max_size=n),
        st.builds(lambda v, k: [v] * k, float32s, st.just(n))))
    n_int = draw(st.sampled_from([0, n, max(0, n - 1), n + 3]))
    msg = T["sensor_msgs/msg/LaserScan"](
        header=draw(headers()), angle_min=draw(float32s), angle_max=draw(float32s), angle_increment=draw(float32s),
        time_increment=draw(float32s), scan_time=draw(float32s), range_min=draw(float32s), range_max=draw(float32s),
        ranges=np.asarray(ranges, dtype=np.float32), intensities=np.zeros(n_int, dtype=np.float32))
    return _roundtrip(msg, "sensor_msgs/msg/LaserScan")


@settings(max_examples=150, **SETTINGS)
@given(laserscans())
def test_decode_laserscan_returns_consistent_arrays_or_a_bagtools_error(msg) -> None:
    result, peak = _call_measured(decode_laserscan, msg)
    _no_foreign_exception(result)
    n = len(msg.ranges)
    assert peak <= 64 * (4 * n) + (256 << 10), f"allocated {peak} bytes for {n} ranges"
    if isinstance(result, BagtoolsError):
        return
    assert result.ranges_m.shape == (n,) and result.angles_rad.shape == (n,)
    assert result.valid.shape == (n,) and result.valid.dtype == bool
    assert result.stamp_ns == int(msg.header.stamp.sec) * 10**9 + int(msg.header.stamp.nanosec)


@settings(max_examples=150, **SETTINGS)
@given(laserscans())
def test_laserscan_valid_returns_are_finite_points(msg) -> None:
    """What the decoder marks valid becomes map points: they must be finite (a NaN or infinite angle, or a
    range_max of 3.4e38, must not pass as a valid return), else the decoder must refuse the scan."""
    try:
        scan = decode_laserscan(msg)
        xy = scan.points_xy()
    except BagtoolsError:
        return
    assert xy.shape == (int(scan.valid.sum()), 2)
    assert np.isfinite(xy).all(), (f"non-finite valid points: angle_min {msg.angle_min}, increment "
                                   f"{msg.angle_increment}, range_min {msg.range_min}, range_max {msg.range_max}")


# ---------------------------------------------------------------------------- PointCloud2


FIELD_NAMES = ["x", "y", "z", "intensity", "rgb", "x"]


@st.composite
def pointclouds(draw):
    layout = draw(st.sampled_from(["plausible", "arbitrary"]))
    if layout == "plausible":  # a sane cloud with one or two lies
        dtype = draw(st.sampled_from([(7, 4), (8, 8), (2, 1), (4, 2), (5, 4)]))
        datatype, size = dtype
        height = draw(st.integers(0, 4))
        width = draw(st.integers(0, 40))
        point_step = draw(st.sampled_from([3 * size, 3 * size + 4, 4 * size, 32]))
        row_step = width * point_step + draw(st.sampled_from([0, 0, 4, 16]))
        offsets = [0, size, 2 * size]
        if draw(st.booleans()):
            offsets[draw(st.integers(0, 2))] = draw(uint32)
        fields = [("x", offsets[0], datatype, 1), ("y", offsets[1], datatype, 1), ("z", offsets[2], datatype, 1)]
        data_len = height * row_step + draw(st.sampled_from([0, 0, -1, 5, -row_step]))
        if draw(st.booleans()):
            which = draw(st.sampled_from(["height", "width", "point_step", "row_step"]))
            lie = draw(uint32)
            height, width, point_step, row_step = (lie if which == "height" else height,
                                                   lie if which == "width" else width,
                                                   lie if which == "point_step" else point_step,
                                                   lie if which == "row_step" else row_step)
    else:
        height, width, point_step, row_step = draw(uint32), draw(uint32), draw(uint32), draw(uint32)
        fields = [(draw(st.sampled_from(FIELD_NAMES)), draw(uint32), draw(st.integers(0, 255)), draw(uint32))
                  for _ in range(draw(st.integers(0, 5)))]
        data_len = draw(st.integers(0, 2048))
    data_len = max(0, min(data_len, 1 << 16))
    data = draw(st.one_of(st.just(bytes(data_len)),
                          st.binary(min_size=min(data_len, 512), max_size=min(data_len, 512)).map(
                              lambda b, n=data_len: (b * (n // max(1, len(b)) + 1))[:n] if b else bytes(n))))
    msg = T["sensor_msgs/msg/PointCloud2"](
        header=draw(headers()), height=height, width=width,
        fields=[T["sensor_msgs/msg/PointField"](name=nm, offset=o, datatype=d, count=c) for nm, o, d, c in fields],
        is_bigendian=draw(st.booleans()), point_step=point_step, row_step=row_step,
        data=np.frombuffer(data, dtype=np.uint8).copy(), is_dense=draw(st.booleans()))
    return _roundtrip(msg, "sensor_msgs/msg/PointCloud2")


@settings(max_examples=200, **SETTINGS)
@given(pointclouds(), st.booleans())
def test_decode_pointcloud2_returns_consistent_points_or_a_bagtools_error(msg, keep_nan) -> None:
    result, peak = _call_measured(decode_pointcloud2, msg, keep_nan)
    _no_foreign_exception(result)
    nbytes = len(msg.data)
    assert peak <= 16 * nbytes + (256 << 10), f"allocated {peak} bytes for a cloud of {nbytes} data bytes"
    if isinstance(result, BagtoolsError):
        return
    points = result.points
    assert points.ndim == 2 and points.shape[1] == 3 and points.dtype == np.float32
    assert points.shape[0] <= int(msg.height) * int(msg.width)
    assert points.shape[0] <= max(nbytes, 0), "more points than data bytes"
    if keep_nan:
        assert points.shape[0] == int(msg.height) * int(msg.width)
    else:
        assert np.isfinite(points).all()


# ---------------------------------------------------------------------------- Odometry and TFMessage


def _vec(draw, name: str):
    return T[name](x=draw(any_float), y=draw(any_float), z=draw(any_float))


@st.composite
def odometries(draw):
    q = T["geometry_msgs/msg/Quaternion"](x=draw(any_float), y=draw(any_float), z=draw(any_float), w=draw(any_float))
    cov = st.lists(any_float, min_size=36, max_size=36).map(lambda v: np.asarray(v, dtype=np.float64))
    msg = T["nav_msgs/msg/Odometry"](
        header=draw(headers()), child_frame_id=draw(frame_ids),
        pose=T["geometry_msgs/msg/PoseWithCovariance"](
            pose=T["geometry_msgs/msg/Pose"](position=_vec(draw, "geometry_msgs/msg/Point"), orientation=q),
            covariance=draw(cov)),
        twist=T["geometry_msgs/msg/TwistWithCovariance"](
            twist=T["geometry_msgs/msg/Twist"](linear=_vec(draw, "geometry_msgs/msg/Vector3"),
                                               angular=_vec(draw, "geometry_msgs/msg/Vector3")),
            covariance=draw(cov)))
    return _roundtrip(msg, "nav_msgs/msg/Odometry")


@settings(max_examples=100, **SETTINGS)
@given(odometries())
def test_decode_odometry_returns_consistent_arrays_or_a_bagtools_error(msg) -> None:
    try:
        sample = decode_odometry(msg)
    except BagtoolsError:
        return
    except Exception as exc:  # noqa: BLE001
        raise AssertionError(f"raised {type(exc).__name__}: {exc}") from exc
    assert sample.position_m.shape == (3,) and sample.orientation_xyzw.shape == (4,)
    assert sample.linear_mps.shape == (3,) and sample.angular_radps.shape == (3,)
    assert sample.pose_covariance.shape == (6, 6) and sample.twist_covariance.shape == (6, 6)
    assert sample.stamp_ns == int(msg.header.stamp.sec) * 10**9 + int(msg.header.stamp.nanosec)


@st.composite
def transforms(draw):
    ts = T["geometry_msgs/msg/TransformStamped"](
        header=draw(headers()), child_frame_id=draw(frame_ids),
        transform=T["geometry_msgs/msg/Transform"](
            translation=_vec(draw, "geometry_msgs/msg/Vector3"),
            rotation=T["geometry_msgs/msg/Quaternion"](x=draw(any_float), y=draw(any_float), z=draw(any_float),
                                                       w=draw(any_float))))
    return ts


@settings(max_examples=100, **SETTINGS)
@given(st.lists(transforms(), max_size=12))
def test_decode_tf_message_returns_parallel_arrays_or_a_bagtools_error(items) -> None:
    msg = _roundtrip(T["tf2_msgs/msg/TFMessage"](transforms=items), "tf2_msgs/msg/TFMessage")
    try:
        arrays = decode_tf_message(msg)
    except BagtoolsError:
        return
    except Exception as exc:  # noqa: BLE001
        raise AssertionError(f"raised {type(exc).__name__}: {exc}") from exc
    n = len(items)
    assert len(arrays) == n
    assert arrays.parent.shape == (n,) and arrays.child.shape == (n,) and arrays.stamp_ns.shape == (n,)
    assert arrays.translation.shape == (n, 3) and arrays.rotation_xyzw.shape == (n, 4)
    assert arrays.stamp_ns.dtype == np.int64
    for i, ts in enumerate(msg.transforms):
        assert int(arrays.stamp_ns[i]) == int(ts.header.stamp.sec) * 10**9 + int(ts.header.stamp.nanosec)


# ---------------------------------------------------------------------------- TfBuffer


FRAMES = ["map", "odom", "base_link", "laser", "/odom", "", "map "]
CHAIN = [("map", "odom"), ("odom", "base_link"), ("base_link", "laser"), ("odom", "base_link")]
TF_STAMPS = [0, 1, 10**9, 2 * 10**9, 2 * 10**9 + 1, 5 * 10**9, 1_700_000_000 * 10**9, -(10**9),
             (2**31 - 1) * 10**9, -(2**31) * 10**9]
UNIT_QUATS = [(0.0, 0.0, 0.0, 1.0), (0.0, 0.0, 1.0, 0.0), (0.0, 0.0, 0.7071067811865476, 0.7071067811865476),
              (0.0, 0.0, -0.7071067811865476, 0.7071067811865476), (0.5, 0.5, 0.5, 0.5), (0.0, 0.0, 0.0, -1.0)]
BAD_QUATS = [(0.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 2.0), (math.nan, 0.0, 0.0, 1.0), (0.0, 0.0, math.inf, 1.0),
             (1e-20, 0.0, 0.0, 1e-20), (0.0, 0.0, 0.0, 1.004)]
TRANSLATION = st.one_of(st.sampled_from([0.0, 1.0, -2.5, 1e30, -1e30, math.nan, math.inf, 1e-300]),
                        st.floats(-50, 50))


@st.composite
def tf_arrays(draw, max_size: int = 25):
    n = draw(st.integers(0, max_size))
    rows = []
    for _ in range(n):
        if draw(st.integers(0, 9)) < 7:  # mostly a plausible tree (map -> odom -> base_link -> laser), so that
            parent, child = draw(st.sampled_from(CHAIN))    # lookups get past the frame checks
            q = draw(st.one_of(st.sampled_from(UNIT_QUATS), st.sampled_from(BAD_QUATS)))
        else:
            parent, child = draw(st.sampled_from(FRAMES)), draw(st.sampled_from(FRAMES))
            q = draw(st.one_of(st.sampled_from(UNIT_QUATS), st.sampled_from(BAD_QUATS),
                               st.tuples(any_float, any_float, any_float, any_float)))
        rows.append((parent, child, draw(st.sampled_from(TF_STAMPS)),
                     (draw(TRANSLATION), draw(TRANSLATION), draw(TRANSLATION)), q))
    if not rows:
        return TfArrays.empty()
    return TfArrays(np.array([r[0] for r in rows], dtype=object), np.array([r[1] for r in rows], dtype=object),
                    np.array([r[2] for r in rows], dtype=np.int64), np.array([r[3] for r in rows], dtype=np.float64),
                    np.array([r[4] for r in rows], dtype=np.float64))


def _assert_rigid(T_: np.ndarray) -> None:
    T_ = T_.reshape(-1, 4, 4)
    assert np.isfinite(T_).all(), "a lookup returned a non-finite transform"
    R = T_[:, :3, :3]
    assert np.allclose(R @ np.swapaxes(R, 1, 2), np.eye(3), atol=1e-6), "rotation is not orthonormal"
    assert np.allclose(np.linalg.det(R), 1.0, atol=1e-6), "rotation is not proper"
    assert np.allclose(T_[:, 3, :], [0, 0, 0, 1]), "bottom row is not [0 0 0 1]"


def _buffer(dynamic, static) -> TfBuffer | None:
    """A buffer as TfBuffer.from_bag builds it (invalid transforms skipped, spikes repaired)."""
    try:
        return TfBuffer.from_arrays(dynamic, static, skip_invalid=True, repair_spikes=True)
    except BagtoolsError:
        return None
    except Exception as exc:  # noqa: BLE001
        raise AssertionError(f"from_arrays raised {type(exc).__name__}: {exc}") from exc


LOOKUP_STAMPS = st.lists(st.sampled_from(TF_STAMPS + [3 * 10**9, 10**9 + 500_000_000]), max_size=5)
FRAME_PAIRS = st.lists(st.tuples(st.sampled_from(FRAMES), st.sampled_from(FRAMES)), min_size=1, max_size=3)


@settings(max_examples=120, **SETTINGS)
@given(tf_arrays(), tf_arrays(max_size=6), FRAME_PAIRS, LOOKUP_STAMPS)
def test_tf_buffer_lookups_are_finite_rigid_transforms_or_tf_exceptions(dynamic, static, pairs, stamps) -> None:
    buffer = _buffer(dynamic, static)
    if buffer is None:
        return
    stamp_array = np.array(stamps, dtype=np.int64)
    for target, source in pairs:
        for when in [None, *stamps[:2], stamp_array]:
            try:
                T_ = buffer.lookup(target, source, when)
            except TransformException:
                continue
            except Exception as exc:  # noqa: BLE001
                raise AssertionError(f"lookup({target!r}, {source!r}, {when}) raised {type(exc).__name__}: {exc}") \
                    from exc
            _assert_rigid(T_)
        try:
            T_, valid = buffer.lookup(target, source, stamp_array, return_mask=True)
        except TransformException:
            continue
        except Exception as exc:  # noqa: BLE001
            raise AssertionError(f"lookup({target!r}, {source!r}, {stamp_array}, return_mask=True) raised "
                                 f"{type(exc).__name__}: {exc}") from exc
        assert valid.shape == stamp_array.shape and T_.shape == (stamp_array.size, 4, 4)
        if valid.any():
            _assert_rigid(T_[valid])
        assert np.isnan(T_[~valid]).all()


@settings(max_examples=100, **SETTINGS)
@given(tf_arrays(max_size=12), FRAME_PAIRS, LOOKUP_STAMPS)
def test_tf_buffer_can_transform_never_raises_and_agrees_with_lookup(dynamic, pairs, stamps) -> None:
    buffer = _buffer(dynamic, None)
    if buffer is None:
        return
    for target, source in pairs:
        for when in [None, *stamps[:2], np.array(stamps, dtype=np.int64)]:
            try:
                can = buffer.can_transform(target, source, when)
            except Exception as exc:  # noqa: BLE001
                raise AssertionError(f"can_transform({target!r}, {source!r}, {when!r}) raised "
                                     f"{type(exc).__name__}: {exc}") from exc
            try:
                buffer.lookup(target, source, when)
                ok = True
            except TransformException:
                ok = False
            except Exception:  # noqa: BLE001 - the test above reports it
                continue
            if np.ndim(when) == 0:
                assert bool(can) == ok, f"can_transform({target!r}, {source!r}, {when}) is {can}, lookup {'succeeds' if ok else 'raises'}"
            elif ok:
                assert np.all(can), f"lookup({target!r}, {source!r}, {when}) succeeds, can_transform is {can}"


@settings(max_examples=80, **SETTINGS)
@given(st.sampled_from(FRAMES), st.sampled_from(FRAMES), st.lists(st.sampled_from(TF_STAMPS), min_size=1, max_size=5),
       st.lists(st.tuples(TRANSLATION, TRANSLATION, TRANSLATION), min_size=5, max_size=5),
       st.lists(st.one_of(st.sampled_from(UNIT_QUATS), st.sampled_from(BAD_QUATS)), min_size=5, max_size=5))
def test_tf_buffer_set_transform_accepts_or_raises_invalid_argument(parent, child, stamps, xyz, quats) -> None:
    n = len(stamps)
    buffer = TfBuffer()
    try:
        buffer.set_transform(parent, child, np.array(stamps, dtype=np.int64), np.array(xyz[:n]), np.array(quats[:n]))
    except TransformException:
        return
    except Exception as exc:  # noqa: BLE001
        raise AssertionError(f"set_transform raised {type(exc).__name__}: {exc}") from exc
    # Accepted: every value was finite and every quaternion unit (within tf2's tolerance).
    assert np.isfinite(np.array(xyz[:n])).all() and np.isfinite(np.array(quats[:n])).all()
    for stamp in stamps:
        try:
            T_ = buffer.lookup(parent.lstrip("/") if parent.startswith("/") else parent,
                               child[1:] if child.startswith("/") else child, stamp)
        except TransformException:
            continue
        _assert_rigid(T_)


# ---------------------------------------------------------------------------- TUM files


TUM_TOKENS = ["0", "1", "-1", "0.5", "1e30", "-1e30", "nan", "NaN", "inf", "-inf", "1.7e9", "1700000000.123456789",
              "1000000000000000000000000000000.0", "0.000000001", "-0.0", "1,2", "abc", "0x10", "1_000", "", "#", "٣"]


@st.composite
def tum_texts(draw):
    kind = draw(st.sampled_from(["lines", "text", "binary"]))
    if kind == "text":
        return draw(st.text(max_size=400)).encode("utf-8", "surrogatepass")
    if kind == "binary":
        return draw(st.binary(max_size=400))
    lines = []
    for i in range(draw(st.integers(0, 12))):
        if draw(st.integers(0, 9)) == 0:
            lines.append("# " + draw(st.text(max_size=20)))
            continue
        stamp = draw(st.one_of(st.sampled_from(TUM_TOKENS), st.just(f"{1700000000 + i}.{i:09d}")))
        xyz = [draw(st.one_of(st.sampled_from(TUM_TOKENS), st.floats(-10, 10).map(repr))) for _ in range(3)]
        q = draw(st.one_of(st.just(["0", "0", "0", "1"]), st.just(["0", "0", "0.7071067811865476", "0.7071067811865476"]),
                           st.lists(st.sampled_from(TUM_TOKENS), min_size=4, max_size=4)))
        fields = [stamp, *xyz, *q]
        if draw(st.integers(0, 9)) == 0:
            fields = fields[: draw(st.integers(0, 9))]
        lines.append(draw(st.sampled_from([" ", "\t", ", "])).join(fields))
    return ("\n".join(lines) + draw(st.sampled_from(["", "\n", "\r\n"]))).encode("utf-8")


@settings(max_examples=250, **SETTINGS)
@given(tum_texts())
def test_read_tum_returns_a_valid_trajectory_or_a_bagtools_error(content) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "traj.tum"
        path.write_bytes(content)
        try:
            traj = read_tum(path)
        except BagtoolsError:
            return
        except Exception as exc:  # noqa: BLE001
            raise AssertionError(f"read_tum raised {type(exc).__name__}: {exc}") from exc
    n = len(traj)
    assert n >= 1
    assert traj.stamps_ns.shape == (n,) and traj.stamps_ns.dtype == np.int64 and traj.poses.shape == (n, 4, 4)
    assert (traj.stamps_ns >= 0).all()
    assert np.isfinite(traj.poses).all(), "a trajectory with non-finite poses was accepted"
    _assert_rigid(traj.poses)


def test_read_tum_of_a_missing_file_is_a_bagtools_error(tmp_path: Path) -> None:
    with pytest.raises(BagtoolsError):
        read_tum(tmp_path / "missing.tum")
