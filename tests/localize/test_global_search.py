"""The global search of ``bagtools.commands.localize``: one scan placed in a whole map, at any heading, no initial pose."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from bagtools.grid import read_nav2_map, write_nav2_map
from bagtools.commands.grid import GridMapOptions, GridMapPipeline
from bagtools.io import open_bag
from bagtools.commands.localize import GlobalLocalizer
from bagtools.commands.ndt_odom import NdtOdomOptions
from bagtools.odometry.pipeline import laser_dataset
from bagtools.simtruth import read_ground_truth
from bagtools.transforms import tform2pose


def _angle(a: float) -> float:
    return (a + math.pi) % (2 * math.pi) - math.pi


def test_occupied_points_are_cell_centres_placed_by_the_origin(tmp_path: Path) -> None:
    """A 4 x 3 image (row 0 at the top), one black pixel at row 0, column 1; origin [1, 2, 90 degrees]."""
    pixels = np.full((3, 4), 254, dtype=np.uint8)
    pixels[0, 1] = 0
    (tmp_path / "m.pgm").write_bytes(b"P5\n4 3\n255\n" + pixels.tobytes())
    (tmp_path / "m.yaml").write_text("image: m.pgm\nresolution: 0.5\norigin: [1.0, 2.0, 1.5707963267948966]\n"
                                     "negate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n")
    points = read_nav2_map(tmp_path / "m.yaml").occupied_points()
    # the cell's centre in the image frame: x = 1.5 cells, y = 2.5 cells up from the bottom edge; turned by 90 deg
    np.testing.assert_allclose(points, [[1.0 - 2.5 * 0.5, 2.0 + 1.5 * 0.5]], atol=1e-12)


def _room_scan(pose: np.ndarray, half: tuple[float, float], n: int = 360) -> np.ndarray:
    """A 360-degree scan (n beams, scan frame) of an empty axis-aligned room centred on the origin."""
    angles = np.arange(n) * 2 * np.pi / n
    world = pose[2] + angles
    c, s = np.cos(world), np.sin(world)
    with np.errstate(divide="ignore"):
        tx = np.where(c > 0, (half[0] - pose[0]) / c, (-half[0] - pose[0]) / c)
        ty = np.where(s > 0, (half[1] - pose[1]) / s, (-half[1] - pose[1]) / s)
    r = np.minimum(np.abs(tx), np.abs(ty))
    return np.c_[r * np.cos(angles), r * np.sin(angles)]


def _room_walls(half: tuple[float, float], step: float = 0.05) -> np.ndarray:
    """Points (N, 2) every ``step`` along the walls of a bare room of half-sizes ``half`` (m) centred on 0."""
    x = np.arange(-half[0], half[0] + 1e-9, step)
    y = np.arange(-half[1], half[1] + 1e-9, step)
    return np.r_[np.c_[x, np.full_like(x, half[1])], np.c_[x, np.full_like(x, -half[1])],
                 np.c_[np.full_like(y, half[0]), y], np.c_[np.full_like(y, -half[0]), y]]


def test_a_symmetric_room_gives_both_places() -> None:
    """A bare 10 m x 6 m room looks the same turned by 180 degrees: both places come back, scoring alike."""
    half = (5.0, 3.0)
    walls = _room_walls(half)
    truth = np.array([2.0, 1.0, 0.3])
    hyps = GlobalLocalizer(walls).search(_room_scan(truth, half))
    assert len(hyps) >= 2 and hyps[1].score > 0.95 * hyps[0].score, hyps
    twin = np.array([-2.0, -1.0, _angle(0.3 + math.pi)])
    for place in (truth, twin):
        assert any(np.hypot(*(h.pose[:2] - place[:2])) < 0.1 and abs(_angle(h.pose[2] - place[2])) < 0.03
                   for h in hyps[:2]), (place, hyps)


def test_a_map_with_too_few_occupied_places_is_refused() -> None:
    with pytest.raises(ValueError, match="at least 5 occupied places"):
        GlobalLocalizer(np.zeros((3, 2)))


def test_real_csail_scans_are_placed_in_the_map_from_one_scan_each(real_dir: Path, tmp_path: Path) -> None:
    """The CSAIL building (50 m x 82 m) mapped at 5 cm from its reference poses; 20 scans along the 380 m path,
    each placed with no initial pose. The place is always among the hypotheses (within 30 cm and 3 degrees of the
    reference: the search's first fix, which tracking refines; the reference itself is GMapping's, and along a
    corridor the 5 cm map says little more), and nearly always the best: from scan 325 a corridor 12 m away
    scores 0.922 to the place's 0.908, which only the next scans can decide."""
    bag = real_dir / "csail_scans"
    if not bag.is_dir():
        pytest.skip(f"real bag not available: {bag}")
    options = GridMapOptions(poses="ground-truth", frame="map", resolution=20.0, max_range_m=20.0)  # as slam maps
    grid = GridMapPipeline(bag, options).run().grid
    localizer = GlobalLocalizer.from_map(read_nav2_map(write_nav2_map(grid, tmp_path / "map")))
    with open_bag(bag) as reader:
        scans = laser_dataset(NdtOdomOptions()).read(reader)  # the scans as the front end takes them
        stamps, T_map_base, _ = read_ground_truth(reader)  # as the map was made from
    order = scans.order
    truth = tform2pose(T_map_base[np.searchsorted(stamps, scans.stamps_ns[order])])
    rank = {}
    for k in range(5, 400, 20):
        hyps = localizer.search(scans.points_base(int(order[k])))  # in the base frame
        right = [i for i, h in enumerate(hyps) if np.hypot(*(h.pose[:2] - truth[k, :2])) < 0.3
                 and abs(_angle(h.pose[2] - truth[k, 2])) < math.radians(3.0)]
        rank[k] = right[0] if right else None
    assert all(r is not None for r in rank.values()), rank
    assert sum(r == 0 for r in rank.values()) >= 18, rank


def test_known_places_are_the_free_and_occupied_cells_placed_by_the_origin(tmp_path: Path) -> None:
    """A 4 x 3 image: row 0 all unknown (205), the rest free, one black pixel; origin [1, 2, 90 degrees]."""
    pixels = np.full((3, 4), 254, dtype=np.uint8)
    pixels[0, :] = 205
    pixels[1, 2] = 0
    (tmp_path / "m.pgm").write_bytes(b"P5\n4 3\n255\n" + pixels.tobytes())
    (tmp_path / "m.yaml").write_text("image: m.pgm\nresolution: 0.5\norigin: [1.0, 2.0, 1.5707963267948966]\n"
                                     "negate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n")
    nav2 = read_nav2_map(tmp_path / "m.yaml")
    # image column c, row r (from the top) has its centre at x = (c + 0.5) * 0.5, y = (3 - r - 0.5) * 0.5 in the
    # image frame, turned by 90 degrees about the origin: map x = 1 - y_img, map y = 2 + x_img
    def centre(r: int, c: int) -> list[float]:
        return [1.0 - (3 - r - 0.5) * 0.5, 2.0 + (c + 0.5) * 0.5]
    places = np.array([centre(0, 1), centre(1, 2), centre(2, 3), [10.0, 10.0]])
    assert nav2.known(places).tolist() == [False, True, True, False]
