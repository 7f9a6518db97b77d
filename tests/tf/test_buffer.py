"""TfBuffer against tf2's own test cases (test_tf2 buffer_core_test, tf2 simple/cache tests), numbers from their definitions."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from bagtools.errors import BagtoolsError
from bagtools.tf import (
    BackwardExtrapolationException,
    ConnectivityException,
    ExtrapolationException,
    ForwardExtrapolationException,
    InvalidArgumentException,
    LookupException,
    NoDataForExtrapolationException,
    TfBuffer,
    TransformException,
)

S = 1_000_000_000  # ns per second
IDENTITY_Q = (0.0, 0.0, 0.0, 1.0)


def yaw_q(yaw: float) -> tuple[float, float, float, float]:
    return (0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2))


def pose(T: np.ndarray) -> tuple[np.ndarray, float]:
    """Translation and yaw of a planar 4x4 transform."""
    return T[:3, 3], math.atan2(T[1, 0], T[0, 0])


def angle_diff(a: float, b: float) -> float:
    return abs((a - b + math.pi) % (2 * math.pi) - math.pi)


# ---------------------------------------------------------------- the i, y and v trees of buffer_core_test

TREES = {
    # child: (parent, dx, dy), identity rotations
    "i": {"b": ("a", 1, 0), "c": ("b", 1, 0)},
    "y": {"b": ("a", 1, 0), "c": ("b", 1, 0), "d": ("b", 0, 1), "e": ("d", 0, 1)},
    "v": {"b": ("a", 1, 0), "c": ("b", 1, 0), "f": ("a", 0, 1), "g": ("f", 0, 1)},
}


def positions(tree: dict) -> dict[str, np.ndarray]:
    pos = {"a": np.zeros(3)}
    while len(pos) <= len(tree):
        for child, (parent, dx, dy) in tree.items():
            if parent in pos and child not in pos:
                pos[child] = pos[parent] + [dx, dy, 0.0]
    return pos


def setup_tree(mode: str, stamp_ns: int, spacing_ns: int = 0) -> TfBuffer:
    """As setupTree: one sample at the stamp, or two samples spacing/2 either side of it."""
    buf = TfBuffer()
    stamps = [stamp_ns] if spacing_ns == 0 else [stamp_ns - spacing_ns // 2, stamp_ns + spacing_ns // 2]
    for child, (parent, dx, dy) in TREES[mode].items():
        for s in stamps:
            buf.set_transform(parent, child, s, (dx, dy, 0.0), IDENTITY_Q)
    return buf


@pytest.mark.parametrize("mode", sorted(TREES))
@pytest.mark.parametrize("spacing_ns", [0, S, S // 1000, S // 10])
@pytest.mark.parametrize("when", ["at stamp", "latest"])
def test_trees_all_pairs(mode: str, spacing_ns: int, when: str) -> None:
    stamp = 10 * S
    buf = setup_tree(mode, stamp, spacing_ns)
    pos = positions(TREES[mode])
    for target, source in itertools.product(pos, pos):
        T = buf.lookup(target, source, stamp if when == "at stamp" else None)
        np.testing.assert_allclose(T[:3, 3], pos[source] - pos[target], atol=1e-12)
        np.testing.assert_allclose(T[:3, :3], np.eye(3), atol=1e-12)


def test_disconnected_trees_raise_connectivity() -> None:
    buf = setup_tree("v", 10 * S)
    buf.set_transform("1", "2", 10 * S, (1, 0, 0), IDENTITY_Q)  # the "1_v" setup
    for a, b in [("a", "1"), ("2", "g"), ("c", "2")]:
        with pytest.raises(ConnectivityException, match="not part of the same tree"):
            buf.lookup(a, b, 10 * S)
        assert buf.can_transform(a, b, 10 * S) is False
    with pytest.raises(ConnectivityException):
        buf.lookup("a", "1")  # the latest common time needs a path too


# ---------------------------------------------------------------- ring of 45 degree links

RING = list("abcdefghi")


def ring_buffer(stamp_ns: int) -> TfBuffer:
    buf = TfBuffer()
    for parent, child in zip(RING, RING[1:]):
        step = math.pi / 4
        buf.set_transform(parent, child, stamp_ns, (math.cos(step) - 1, math.sin(step), 0.0), yaw_q(step))
    return buf


@pytest.mark.parametrize("stamp_ns", [1 * S, 10 * S, None])
def test_ring_45(stamp_ns: int | None) -> None:
    """Frame k sits at angle k*45deg on a unit circle around (-1, 0), rotated by k*45deg."""
    buf = ring_buffer(stamp_ns if stamp_ns is not None else 3 * S)
    for (i, target), (j, source) in itertools.product(enumerate(RING), enumerate(RING)):
        k = (j - i) * math.pi / 4
        translation, yaw = pose(buf.lookup(target, source, stamp_ns))
        np.testing.assert_allclose(translation, [math.cos(k) - 1, math.sin(k), 0.0], atol=1e-9)
        assert angle_diff(yaw, k) < 1e-9


def test_ring_batch_matches_single_lookups() -> None:
    buf = TfBuffer()
    stamps = np.arange(0, 11) * S
    for n, (parent, child) in enumerate(zip(RING, RING[1:])):
        yaws = (n + 1) * 0.1 * np.arange(11)
        buf.set_transform(parent, child, stamps, np.c_[np.cos(yaws), np.sin(yaws), np.zeros(11)],
                          np.array([yaw_q(y) for y in yaws]))
    query = np.array([0, S // 3, 5 * S + 7, 10 * S, 2 * S])
    batch = buf.lookup("c", "h", query)
    assert batch.shape == (5, 4, 4)
    for k, s in enumerate(query):
        np.testing.assert_allclose(batch[k], buf.lookup("c", "h", int(s)), atol=1e-12)


# ---------------------------------------------------------------- compound transforms (compound_xfm_configuration)

def rpy_matrix(roll: float, pitch: float, yaw: float, xyz) -> np.ndarray:
    cr, sr, cp, sp, cy, sy = math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch), math.cos(yaw), math.sin(yaw)
    T = np.eye(4)
    T[:3, :3] = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]]) @ np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]]) \
        @ np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    T[:3, 3] = xyz
    return T


def matrix_to_xyzw(R: np.ndarray) -> np.ndarray:
    w = math.sqrt(max(0.0, 1 + R[0, 0] + R[1, 1] + R[2, 2])) / 2
    if w > 1e-3:
        return np.array([(R[2, 1] - R[1, 2]) / (4 * w), (R[0, 2] - R[2, 0]) / (4 * w), (R[1, 0] - R[0, 1]) / (4 * w), w])
    raise ValueError("test rotations stay away from 180 degrees")


def test_compound_transforms() -> None:
    """root->a and root->b->c->d with full 3-D rotations (btQuaternion.setEuler(yaw, pitch, roll))."""
    edges = {
        "a": ("root", rpy_matrix(0.75, 0.5, 0.25, (1, 1, 1))),
        "b": ("root", rpy_matrix(0.5, 0.25, 1.0, (-1, 0, -1))),
        "c": ("b", rpy_matrix(1.25, 0.75, 0.25, (0, 2, 0.5))),
        "d": ("c", rpy_matrix(-0.75, 1.0, -0.5, (0.5, -1, 1.5))),
    }
    buf = TfBuffer()
    for child, (parent, T) in edges.items():
        buf.set_transform(parent, child, 0, T[:3, 3], matrix_to_xyzw(T[:3, :3]))
    in_root = {"root": np.eye(4), "a": edges["a"][1], "b": edges["b"][1]}
    in_root["c"] = in_root["b"] @ edges["c"][1]
    in_root["d"] = in_root["c"] @ edges["d"][1]
    for target, source in itertools.permutations(in_root, 2):
        expected = np.linalg.inv(in_root[target]) @ in_root[source]
        np.testing.assert_allclose(buf.lookup(target, source), expected, atol=1e-9)


# ---------------------------------------------------------------- helix (interpolation and time travel)

def helix_buffer() -> tuple[TfBuffer, int, int, int]:
    t0, step, t1 = 10 * S, S // 20, 15 * S
    theta, vel = 0.25, 1.0
    buf = TfBuffer()
    stamps = np.arange(t0, t1 + 1, step)
    dt = (stamps - t0) / S
    dt2 = (stamps + step // 2 - t0) / S
    zeros, ones = np.zeros_like(dt), np.ones_like(dt)
    buf.set_transform("a", "b", stamps, np.c_[zeros, zeros, vel * dt], np.c_[zeros, zeros, zeros, ones])
    buf.set_transform("b", "c", stamps, np.c_[np.cos(theta * dt), np.sin(theta * dt), zeros],
                      np.array([yaw_q(theta * x) for x in dt]))
    buf.set_transform("a", "d", stamps + step // 2, np.c_[zeros, zeros, np.cos(theta * dt2)],
                      np.c_[zeros, zeros, zeros, ones])
    return buf, t0, step, t1


def test_helix_interpolation_and_time_travel() -> None:
    buf, t0, step, t1 = helix_buffer()
    theta, vel, eps = 0.25, 1.0, 2e-5
    t = np.arange(t0 + step // 2, t1, step)
    dt = (t - t0) / S
    T_ab = buf.lookup("a", "b", t)
    np.testing.assert_allclose(T_ab[:, 2, 3], vel * dt, atol=eps)
    T_ac = buf.lookup("a", "c", t)
    np.testing.assert_allclose(T_ac[:, 0, 3], np.cos(theta * dt), atol=eps)
    np.testing.assert_allclose(T_ac[:, 1, 3], np.sin(theta * dt), atol=eps)
    np.testing.assert_allclose(T_ac[:, 2, 3], vel * dt, atol=eps)
    np.testing.assert_allclose(np.arctan2(T_ac[:, 1, 0], T_ac[:, 0, 0]), theta * dt, atol=eps)
    np.testing.assert_allclose(buf.lookup("a", "d", t)[:, 2, 3], np.cos(theta * dt), atol=eps)
    t2 = t + step // 2
    dt2 = (t2 - t0) / S
    T_cd = buf.lookup("c", "d", t2)
    np.testing.assert_allclose(T_cd[:, 0, 3], -1, atol=eps)
    np.testing.assert_allclose(T_cd[:, 1, 3], 0, atol=eps)
    np.testing.assert_allclose(T_cd[:, 2, 3], np.cos(theta * dt2) - vel * dt2, atol=eps)
    np.testing.assert_allclose(np.arctan2(T_cd[:, 1, 0], T_cd[:, 0, 0]), -theta * dt2, atol=eps)
    # Advanced API: c at t, d at t + step, through the fixed frame a.
    t = np.arange(t0 + step // 2, t1 - step, 2 * step)
    dt, dt2 = (t - t0) / S, (t + step - t0) / S
    T = buf.lookup_full("c", t, "d", t + step, "a")
    np.testing.assert_allclose(T[:, 0, 3], -1, atol=eps)
    np.testing.assert_allclose(T[:, 1, 3], 0, atol=eps)
    np.testing.assert_allclose(T[:, 2, 3], np.cos(theta * dt2) - vel * dt, atol=eps)
    np.testing.assert_allclose(np.arctan2(T[:, 1, 0], T[:, 0, 0]), -theta * dt, atol=eps)
    for k in (0, len(t) // 2):
        np.testing.assert_allclose(buf.lookup_full("c", int(t[k]), "d", int(t[k] + step), "a"), T[k], atol=1e-12)
    assert buf.can_transform_full("c", t, "d", t + step, "a").all()
    assert not buf.can_transform_full("c", t1 + 1, "d", t0, "a")


# ---------------------------------------------------------------- interpolation rules

def test_interpolation_lerp_slerp_and_exact_samples() -> None:
    buf = TfBuffer()
    buf.set_transform("p", "c", np.array([0, 10 * S]), np.array([[0, 0, 0], [2, 4, 0]]), np.array([yaw_q(0.0), yaw_q(1.0)]))
    T = buf.lookup("p", "c", np.array([0, 2 * S, 5 * S, 10 * S]))
    np.testing.assert_allclose(T[:, 0, 3], [0, 0.4, 1.0, 2.0], atol=1e-12)
    np.testing.assert_allclose(np.arctan2(T[:, 1, 0], T[:, 0, 0]), [0, 0.2, 0.5, 1.0], atol=1e-12)
    translation, rotation = buf.lookup_pose("p", "c", 10 * S)
    assert translation.tolist() == [2.0, 4.0, 0.0]            # a stamp equal to a sample returns it exactly
    np.testing.assert_array_equal(rotation, yaw_q(1.0))


def test_slerp_takes_the_shortest_path() -> None:
    buf = TfBuffer()
    q0, q1 = np.array(yaw_q(3.0)), -np.array(yaw_q(-3.0))    # 0.28 rad apart through +-pi, q1 in the other hemisphere
    buf.set_transform("p", "c", np.array([0, 2 * S]), np.zeros((2, 3)), np.array([q0, q1]))
    _, yaw = pose(buf.lookup("p", "c", S))
    assert angle_diff(yaw, math.pi) < 1e-12


def test_out_of_order_samples_are_sorted_and_duplicates_dropped() -> None:
    buf = TfBuffer()
    for s in [3, 1, 2, 1, 3]:
        buf.set_transform("p", "c", s * S, (s, 0, 0), IDENTITY_Q)
    np.testing.assert_allclose(buf.lookup("p", "c", np.array([1, 2, 3]) * S)[:, 0, 3], [1, 2, 3])
    assert buf.frame_time_range("c") == (S, 3 * S)
    assert buf._frames[buf._ids["c"]].compile().stamps.size == 3
    buf.set_transform("p", "c", 2 * S, (20, 0, 0), IDENTITY_Q)   # same stamp, new value: the last set wins
    assert buf.lookup("p", "c", 2 * S)[0, 3] == 20


def test_parent_change_has_no_interpolation_across_it() -> None:
    buf = TfBuffer()
    buf.set_transform("a", "x", np.array([0, S]), np.array([[0, 0, 0], [1, 0, 0]]), [IDENTITY_Q] * 2)
    buf.set_transform("b", "x", np.array([2 * S, 3 * S]), np.array([[10, 0, 0], [11, 0, 0]]), [IDENTITY_Q] * 2)
    buf.set_transform("root", "a", 0, (0, 0, 0), IDENTITY_Q, static=True)
    stamps = np.array([S // 2, 3 * S // 2, 2 * S, 5 * S // 2])
    # Until b is attached to root, x is unreachable from root once it hangs below b.
    T, valid = buf.lookup("root", "x", stamps, return_mask=True)
    assert valid.tolist() == [True, True, False, False]
    with pytest.raises(ConnectivityException, match="'root' and 'x'"):
        buf.lookup("root", "x", stamps)
    buf.set_transform("root", "b", 0, (0, 100, 0), IDENTITY_Q, static=True)
    T = buf.lookup("root", "x", stamps)
    # 0.5 s: between two samples with parent a; 1.5 s: parent change ahead, the older sample (parent a) holds;
    # 2.0 s: exactly the first sample with parent b; 2.5 s: interpolated with parent b.
    np.testing.assert_allclose(T[:, :2, 3], [[0.5, 0], [1, 0], [10, 100], [10.5, 100]], atol=1e-12)
    assert buf.parent("x", 3 * S // 2) == "a" and buf.parent("x", 2 * S) == "b" and buf.parent("x") == "b"
    np.testing.assert_allclose(buf.lookup("a", "x", stamps)[:, :2, 3], [[0.5, 0], [1, 0], [10, 100], [10.5, 100]])
    np.testing.assert_allclose(buf.lookup("x", "b", np.array([S // 2, 5 * S // 2]))[:, :2, 3], [[-0.5, 100], [-10.5, 0]])


# ---------------------------------------------------------------- extrapolation, single samples, statics

def test_extrapolation_messages_like_tf2() -> None:
    buf = TfBuffer()
    buf.set_transform("foo", "bar", np.array([2 * S, 3 * S]), np.zeros((2, 3)), [IDENTITY_Q] * 2)
    with pytest.raises(BackwardExtrapolationException) as past:
        buf.lookup("foo", "bar", S)
    assert str(past.value) == ("Lookup would require extrapolation into the past.  Requested time 1.000000 but the "
                               "earliest data is at time 2.000000, when looking up transform from frame [bar] to frame [foo]")
    with pytest.raises(ForwardExtrapolationException) as future:
        buf.lookup("foo", "bar", np.array([2 * S, 4 * S + 500]))
    assert str(future.value) == ("Lookup would require extrapolation into the future.  Requested time 4.000001 but the "
                                 "latest data is at time 3.000000, when looking up transform from frame [bar] to frame [foo]")
    assert isinstance(future.value, ExtrapolationException) and isinstance(future.value, TransformException)
    assert isinstance(future.value, BagtoolsError)
    T, valid = buf.lookup("foo", "bar", np.array([S, 2 * S, 4 * S]), return_mask=True)
    assert valid.tolist() == [False, True, False]
    assert np.isnan(T[0]).all() and np.isnan(T[2]).all() and not np.isnan(T[1]).any()
    assert buf.can_transform("foo", "bar", np.array([S, 2 * S])).tolist() == [False, True]


def test_single_sample_valid_only_at_its_stamp_or_latest() -> None:
    buf = TfBuffer()
    buf.set_transform("foo", "bar", 2 * S, (1, 2, 3), IDENTITY_Q)
    assert buf.lookup("foo", "bar", 2 * S)[0, 3] == 1
    assert buf.lookup("foo", "bar")[2, 3] == 3
    with pytest.raises(NoDataForExtrapolationException, match=r"extrapolation at time 4.000000, but only time 2.000000"):
        buf.lookup("foo", "bar", 4 * S)


def test_statics_valid_at_any_time_and_ignored_for_latest() -> None:
    buf = TfBuffer()
    buf.set_transform("base_link", "laser", S, (0.1, 0, 0.2), IDENTITY_Q, static=True)
    assert buf.lookup("base_link", "laser", 2 * S)[0, 3] == pytest.approx(0.1)
    assert buf.lookup("laser", "base_link", -5)[2, 3] == pytest.approx(-0.2)
    assert buf.latest_common_time("base_link", "laser") is None
    buf.set_transform("odom", "base_link", np.array([5, 7]) * S, np.array([[1, 0, 0], [2, 0, 0]]), [IDENTITY_Q] * 2)
    buf.set_transform("map", "odom", np.array([4, 6]) * S, np.zeros((2, 3)), [IDENTITY_Q] * 2)
    assert buf.latest_common_time("laser", "odom") == 7 * S
    assert buf.latest_common_time("map", "laser") == 6 * S     # the minimum over the chain's latest stamps
    assert buf.lookup("map", "laser")[0, 3] == pytest.approx(1.5 + 0.1)
    assert buf.time_range("map", "laser") == (5 * S, 6 * S)
    # A later static set replaces the transform (tf2's StaticCache holds one).
    buf.set_transform("base_link", "laser", 9 * S, (0.3, 0, 0), IDENTITY_Q, static=True)
    assert buf.lookup("base_link", "laser", 0)[0, 3] == pytest.approx(0.3)


def test_lookup_inside_a_branch_ignores_extrapolation_above_it() -> None:
    """tf2 only needs data up to the common ancestor: base_link <- laser and base_link <- camera."""
    buf = TfBuffer()
    buf.set_transform("odom", "base_link", np.array([5, 7]) * S, np.zeros((2, 3)), [IDENTITY_Q] * 2)
    buf.set_transform("base_link", "laser", 0, (1, 0, 0), IDENTITY_Q, static=True)
    buf.set_transform("base_link", "camera", 0, (0, 1, 0), IDENTITY_Q, static=True)
    np.testing.assert_allclose(buf.lookup("laser", "camera", 100 * S)[:2, 3], [-1, 1])
    with pytest.raises(ForwardExtrapolationException, match=r"from frame \[camera\] to frame \[odom\]"):
        buf.lookup("odom", "camera", 100 * S)


# ---------------------------------------------------------------- ids and arguments

def test_leading_slash_stripped_when_set_and_rejected_when_looked_up() -> None:
    buf = TfBuffer()
    buf.set_transform("/odom", "/base_link", 0, (1, 0, 0), IDENTITY_Q)
    assert buf.frames == ["base_link", "odom"]
    assert buf.lookup("odom", "base_link", 0)[0, 3] == 1
    with pytest.raises(InvalidArgumentException, match="cannot start with a '/'"):
        buf.lookup("/odom", "base_link", 0)
    with pytest.raises(InvalidArgumentException, match="cannot be empty"):
        buf.lookup("", "base_link", 0)
    assert buf.can_transform("/odom", "base_link", 0) is False


def test_unknown_frames_raise_lookup_exception_naming_known_ones() -> None:
    buf = TfBuffer()
    with pytest.raises(LookupException):
        buf.lookup("a", "b", S)                                  # nothing exists
    buf.set_transform("foo", "child", S, (0, 0, 0), IDENTITY_Q)
    with pytest.raises(LookupException, match=r'"bar" passed to lookupTransform argument source_frame does not exist.*'
                                              r"Known frames: child, foo"):
        buf.lookup("foo", "bar", S)
    assert buf.can_transform("foo", "bar", S) is False


@pytest.mark.parametrize("translation, rotation, match", [
    ((math.nan, 0, 0), IDENTITY_Q, "NaN"),
    ((0, 0, 0), (0, 0, 0, 0), "not normalized"),
    ((0, 0, 0), (0, 0, 0, 1.02), "not normalized"),
    ((0, 0, 1e30), IDENTITY_Q, "beyond 1e\\+09 m"),
    ((-3.4e38, 0, 0), IDENTITY_Q, "beyond 1e\\+09 m"),
])
def test_invalid_transforms_are_rejected(translation, rotation, match) -> None:
    buf = TfBuffer()
    with pytest.raises(InvalidArgumentException, match=match):
        buf.set_transform("p", "c", S, translation, rotation)
    assert buf.frames == []


def test_invalid_frame_ids_and_stamps_are_rejected() -> None:
    buf = TfBuffer()
    with pytest.raises(InvalidArgumentException, match="are the same"):
        buf.set_transform("same_frame", "same_frame", S, (0, 0, 0), IDENTITY_Q)
    with pytest.raises(InvalidArgumentException, match="child_frame_id is empty"):
        buf.set_transform("p", "/", S, (0, 0, 0), IDENTITY_Q)
    with pytest.raises(InvalidArgumentException, match="parent"):
        buf.set_transform("", "c", S, (0, 0, 0), IDENTITY_Q)
    with pytest.raises(InvalidArgumentException, match="integer nanoseconds"):
        buf.set_transform("p", "c", 1.5, (0, 0, 0), IDENTITY_Q)
    buf.set_transform("p", "c", np.array([0, S]), np.zeros((2, 3)), [IDENTITY_Q] * 2)
    with pytest.raises(InvalidArgumentException, match="integer nanoseconds"):
        buf.lookup("p", "c", np.array([0.5]))


def test_nearly_unit_quaternions_are_accepted_and_normalized() -> None:
    buf = TfBuffer()
    buf.set_transform("p", "c", 0, (0, 0, 0), (0, 0, 0, 1.004))
    np.testing.assert_allclose(buf.lookup("p", "c", 0), np.eye(4), atol=1e-15)


def test_invalid_rows_skipped_when_loading_with_skip_invalid() -> None:
    from bagtools.io import TfArrays

    arrays = TfArrays(np.array(["odom", "odom", "odom"], dtype=object), np.array(["base", "base", "odom"], dtype=object),
                      np.array([0, S, 2 * S]), np.array([[0, 0, 0], [np.nan, 0, 0], [0, 0, 0]]), np.tile(IDENTITY_Q, (3, 1)))
    buf = TfBuffer.from_arrays(arrays, None, skip_invalid=True)
    assert buf.frame_time_range("base") == (0, 0)
    assert len(buf.warnings) == 2 and "NaN" in buf.warnings[0] + buf.warnings[1]


def test_far_off_translations_are_skipped_when_loading_and_said_without_numpy_noise() -> None:
    """1e30 m (or +-1e300 m) on every sample of an edge is too persistent to be a spike: the buffer refuses it as it
    refuses a NaN (it collapsed map-cloud's picture and grid's raster to no extent: an internal error), and the
    repairs before it do not overflow on it."""
    import warnings

    from bagtools.io import TfArrays

    n = 20
    far = np.zeros((n, 3))
    far[: n // 2, 0], far[n // 2:, 0] = 1e300, -1e300
    arrays = TfArrays(np.full(n, "odom", dtype=object), np.full(n, "base", dtype=object), np.arange(n) * S // 10,
                      far, np.tile(IDENTITY_Q, (n, 1)))
    static = TfArrays(np.array(["base"], dtype=object), np.array(["camera"], dtype=object), np.array([0]),
                      np.array([[0.0, 0.0, 1e30]]), np.array([IDENTITY_Q]))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        buf = TfBuffer.from_arrays(arrays, static, skip_invalid=True, repair_spikes=True)
    assert not buf.has_frame("camera") and not buf.has_frame("odom")
    assert any("translation beyond 1e+09 m" in w for w in buf.warnings), buf.warnings
    assert not any("jumps" in w for w in buf.warnings), buf.warnings
    assert "beyond 1e+09 m" in buf.invalid_note("base")


def test_loop_in_tree_is_a_lookup_exception() -> None:
    buf = TfBuffer()
    buf.set_transform("a", "b", 0, (0, 0, 0), IDENTITY_Q, static=True)
    buf.set_transform("b", "a", 0, (0, 0, 0), IDENTITY_Q, static=True)
    buf.set_transform("c", "d", 0, (0, 0, 0), IDENTITY_Q, static=True)
    with pytest.raises(LookupException, match="loop"):
        buf.lookup("d", "a", 0)


def test_identity_for_same_frame_and_shapes() -> None:
    buf = TfBuffer()
    buf.set_transform("p", "c", np.array([0, S]), np.zeros((2, 3)), [IDENTITY_Q] * 2)
    np.testing.assert_array_equal(buf.lookup("c", "c", 12345), np.eye(4))
    assert buf.lookup("p", "c", np.array([0, 1, 2])).shape == (3, 4, 4)
    assert buf.lookup("p", "c", np.array([], dtype=np.int64)).shape == (0, 4, 4)
    translation, rotation, valid = buf.lookup_pose("p", "c", np.array([0, 2 * S]), return_mask=True)
    assert translation.shape == (2, 3) and rotation.shape == (2, 4) and valid.tolist() == [True, False]


def test_batch_matches_per_stamp_loop_on_random_chain() -> None:
    rng = np.random.default_rng(4)
    buf = TfBuffer()
    for parent, child, n in [("map", "odom", 7), ("odom", "base", 50), ("base", "laser", 1)]:
        q = rng.normal(size=(n, 4))
        stamps = np.sort(rng.choice(100 * S, n, replace=False)) if n > 1 else np.array([0])
        buf.set_transform(parent, child, stamps, rng.normal(size=(n, 3)), q / np.linalg.norm(q, axis=1)[:, None],
                          static=n == 1)
    first, last = buf.time_range("map", "laser")
    query = rng.integers(first, last + 1, 200)
    batch = buf.lookup("laser", "map", query)
    for k in range(0, 200, 17):
        np.testing.assert_allclose(batch[k], buf.lookup("laser", "map", int(query[k])), atol=1e-12)
    R = batch[:, :3, :3]
    np.testing.assert_allclose(R @ R.transpose(0, 2, 1), np.broadcast_to(np.eye(3), R.shape), atol=1e-12)


def test_a_skipped_transform_is_named_as_text_not_as_a_numpy_repr() -> None:
    """Frame ids come from numpy arrays; the warning quotes them as 'odom', not np.str_('odom')."""
    from bagtools.io import TfArrays

    arrays = TfArrays(parent=np.array(["odom", "odom"]), child=np.array(["base_link", "base_link"]),
                      stamp_ns=np.array([1, 2], dtype=np.int64), translation=np.zeros((2, 3)),
                      rotation_xyzw=np.array([[0.0, 0.0, 0.0, 1.0], [0.0, 0.0, 0.0, 2.0]]))
    buf = TfBuffer.from_arrays(arrays, skip_invalid=True)
    assert len(buf.warnings) == 1 and "e.g. 'odom' -> 'base_link' at" in buf.warnings[0], buf.warnings
    assert "np.str_" not in buf.warnings[0]


def test_one_stamp_lookups_equal_the_batched_path_and_fall_back_for_the_rest() -> None:
    """An int stamp takes the one-stamp path (plain floats, a cached chain); it must give the batched path's
    matrices, raise the same errors, fall back where a parent changes, and see transforms added later."""
    rng = np.random.default_rng(5)
    buf = TfBuffer()

    def quats(n: int) -> np.ndarray:
        q = rng.normal(size=(n, 4))
        return q / np.linalg.norm(q, axis=1)[:, None]

    buf.set_transform("map", "odom", np.arange(11) * S, rng.normal(size=(11, 3)), quats(11))
    buf.set_transform("odom", "base", np.arange(31) * S // 3, rng.normal(size=(31, 3)), quats(31))
    buf.set_transform("base", "laser", 0, (0.1, 0.0, 0.2), (0.0, 0.0, 0.0, 1.0), static=True)
    buf.set_transform("base", "arm", 5 * S, (0.0, 0.3, 0.0), IDENTITY_Q)  # one sample only
    # "hand" changes parent at 4 s: the one-stamp path must leave it to the batched path
    buf.set_transform(["base", "base", "laser", "laser"], "hand", np.array([0, 3, 4, 9]) * S,
                      rng.normal(size=(4, 3)), quats(4))
    stamps = np.r_[np.sort(rng.integers(0, 10 * S, 300)), 0, 10 * S, 5 * S]
    for target, source in [("map", "laser"), ("laser", "map"), ("odom", "laser"), ("laser", "base"),
                           ("map", "hand"), ("arm", "laser"), ("map", "base")]:
        ok = buf.can_transform(target, source, stamps)
        batched = buf.lookup(target, source, stamps[ok])
        one = np.array([buf.lookup(target, source, int(s)) for s in stamps[ok]])
        assert np.abs(one - batched).max() <= 1e-12, (target, source)
        for s in stamps[~ok][:5]:
            with pytest.raises(ExtrapolationException):
                buf.lookup(target, source, int(s))
            with pytest.raises(ExtrapolationException):
                buf.lookup(target, source, np.array([s]))
    for s in (-1, 11 * S):
        with pytest.raises(ExtrapolationException, match="extrapolation"):
            buf.lookup("map", "laser", s)
    # np.int64 stamps too; and a transform set later is seen (the cached chain is dropped)
    before = buf.lookup("laser", "map", np.int64(2 * S))
    buf.set_transform("base", "laser", 0, (0.5, 0.0, 0.2), (0.0, 0.0, 0.0, 1.0), static=True)
    after = buf.lookup("laser", "map", np.int64(2 * S))
    assert not np.allclose(before, after)
    assert np.allclose(after, buf.lookup("laser", "map", np.array([2 * S]))[0], atol=1e-12)
