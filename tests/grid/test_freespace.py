"""The free space of a local map: where its rays passed, and how much of another map stands in it."""

from __future__ import annotations

import numpy as np

from bagtools.grid.freespace import FREE_MARGIN_M, FreeSpace


def _room_scan(origin: np.ndarray, n: int = 360) -> np.ndarray:
    """Returns of a laser at ``origin`` inside the square room |x|, |y| <= 3 m, one per degree."""
    a = np.linspace(-np.pi, np.pi, n, endpoint=False)
    d = np.c_[np.cos(a), np.sin(a)]
    t = np.min(np.where(np.abs(d) > 1e-12, (np.sign(d) * 3.0 - origin) / np.where(np.abs(d) > 1e-12, d, 1.0),
                        np.inf), axis=1)
    return origin + d * t[:, None]


def test_points_where_the_rays_passed_are_seen_through_and_walls_are_not() -> None:
    origin = np.array([0.5, -0.5])
    free = FreeSpace.from_scans([(origin, _room_scan(origin))], 0.1)
    assert free.seen_through(np.array([[0.0, 0.0], [-2.0, 1.5], [1.5, 2.0]])) == 1.0  # open floor
    assert free.seen_through(_room_scan(np.zeros(2))) == 0.0  # the same walls, from elsewhere in the room
    assert free.seen_through(np.array([[4.0, 0.0], [0.0, -5.0]])) == 0.0  # behind the walls: never seen
    # the last FREE_MARGIN_M before a return is not counted: a wall a little off is not a contradiction
    assert free.seen_through(np.array([[3.0 - 0.5 * FREE_MARGIN_M, 0.2]])) == 0.0
    assert free.seen_through(np.zeros((0, 2))) == 0.0


def test_the_share_counts_every_point_given() -> None:
    origin = np.zeros(2)
    free = FreeSpace.from_scans([(origin, _room_scan(origin))], 0.1)
    walls = _room_scan(np.array([0.3, 0.2]))
    inside = np.array([[0.0, 1.0], [1.0, 0.0], [-1.0, -1.0]])
    assert abs(free.seen_through(np.vstack([walls, inside])) - 3 / (len(walls) + 3)) < 1e-12


def test_several_scans_add_their_free_space() -> None:
    """A second keyframe sees round a corner the first could not: both are the map's free space."""
    a, b = np.array([-2.0, -2.0]), np.array([2.0, 2.0])
    pillar = np.array([[0.0, 0.0]])
    scans = [(a, _room_scan(a)), (b, _room_scan(b))]
    free = FreeSpace.from_scans(scans, 0.1)
    one = FreeSpace.from_scans(scans[:1], 0.1)
    near_b = np.array([[2.0, 2.6]])
    assert free.seen_through(pillar) == 1.0 and free.seen_through(near_b) == 1.0
    assert one.seen_through(near_b) == 1.0  # the first saw that far too: the room is convex
    assert FreeSpace.from_scans([], 0.1).seen_through(pillar) == 0.0
