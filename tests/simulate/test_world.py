"""Tests for bagtools_simulate.world: loading, ray casts, clearance and surface distances."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from bagtools.errors import BagtoolsError
from bagtools_simulate.world import World, load_world, packaged_world_names
from bagtools_simulate.world import world as world_module

SCAN_Z = 0.131  # base_scan height above the floor on the Waffle


@pytest.fixture(scope="module")
def tb3() -> World:
    return load_world("turtlebot3_world")


def _inner_wall_distance(p: np.ndarray) -> float:
    """Distance from p (inside the shell) to the nearest edge line of the inner hexagon."""
    ring = np.array(load_world("turtlebot3_world").to_json()["shell_wall"]["inner"])
    dists = []
    for a, b in zip(ring, np.roll(ring, -1, axis=0), strict=True):
        e = (b - a) / np.linalg.norm(b - a)
        dists.append(abs(e[0] * (p[1] - a[1]) - e[1] * (p[0] - a[0])))
    return min(dists)


def test_packaged_world_loads_with_all_parts(tb3: World) -> None:
    assert "turtlebot3_world" in packaged_world_names()
    assert tb3.name == "turtlebot3_world"
    assert tb3.spawn_xy_yaw == (-2.0, -0.5, 0.0)
    assert len(tb3.prisms) == 6  # shell wall + five hexagons
    assert len(tb3.cylinders) == 9
    assert tb3.boundary_xy is not None
    assert tb3.bounds_xy == pytest.approx((-2.93294, -2.54, 2.93294, 2.54))


def test_raycast_2d_hits_pillars_at_hand_computed_distances(tb3: World) -> None:
    # Pillars of radius 0.15 m stand at (0, 0) and (1.1, 0).
    d = tb3.raycast_2d(np.array([0.5, 0.0]), np.array([0.0, math.pi]), SCAN_Z, 3.5)
    np.testing.assert_allclose(d, [0.45, 0.35], atol=1e-12)
    # Off-centre: a ray along +x at y = 0.09 meets the pillar at x = 1.1 - sqrt(r^2 - y^2).
    d = tb3.raycast_2d(np.array([0.5, 0.09]), np.array([0.0]), SCAN_Z, 3.5)
    assert d[0] == pytest.approx(1.1 - math.sqrt(0.15**2 - 0.09**2) - 0.5, abs=1e-12)


def test_raycast_2d_hits_inner_shell_wall(tb3: World) -> None:
    # From the spawn point straight left (-x): the inner wall edge from (-2.93294, 0) to (-1.46647, -2.54).
    origin = np.array([-2.0, -0.5])
    x_wall = -2.93294 + (0.5 / 2.54) * 1.46647
    d = tb3.raycast_2d(origin, np.array([math.pi]), SCAN_Z, 3.5)
    assert d[0] == pytest.approx(-2.0 - x_wall, abs=1e-9)


def test_raycast_2d_only_sees_solids_at_its_height(tb3: World) -> None:
    # At z = 0.6 the 0.5 m pillars are below the beam; the head hexagon (vertex at x = 2.32682) is hit.
    d = tb3.raycast_2d(np.array([0.5, 0.0]), np.array([0.0]), 0.6, 3.5)
    assert d[0] == pytest.approx(2.32682 - 0.5, abs=1e-9)


def test_raycast_2d_reports_inf_beyond_max_range(tb3: World) -> None:
    d = tb3.raycast_2d(np.array([0.5, 0.0]), np.array([0.0, math.pi]), SCAN_Z, 0.4)
    assert np.isposinf(d[0])
    assert d[1] == pytest.approx(0.35)


def test_raycast_2d_matches_marching_along_the_ray(tb3: World) -> None:
    """Independent check: march 1 mm steps along each ray until clearance turns negative."""
    rng = np.random.default_rng(3)
    origins = []
    while len(origins) < 6:
        p = rng.uniform(-2.5, 2.5, size=2)
        if tb3.clearance_m(p[None], (SCAN_Z - 1e-6, SCAN_Z + 1e-6))[0] > 0.1:
            origins.append(p)
    angles = rng.uniform(-math.pi, math.pi, size=12)
    steps = np.arange(1, 3501) * 1e-3
    for origin in origins:
        d = tb3.raycast_2d(origin, angles, SCAN_Z, 3.5)
        for angle, dist in zip(angles, d, strict=True):
            pts = origin + steps[:, None] * np.array([math.cos(angle), math.sin(angle)])
            c = tb3.clearance_m(pts, (SCAN_Z - 1e-6, SCAN_Z + 1e-6))
            blocked = np.flatnonzero(c < 0.0)
            if len(blocked) == 0:
                assert np.isposinf(dist) or dist > 3.499
            else:
                assert dist == pytest.approx(steps[blocked[0]], abs=1.5e-3)


def test_raycast_3d_downward_rays_hit_floor_at_z_over_cos(tb3: World) -> None:
    origin = np.array([-2.0, -0.5, 0.2])
    tilt = np.deg2rad([0.0, 10.0, 30.0, 45.0])
    dirs = np.stack([np.sin(tilt), np.zeros_like(tilt), -np.cos(tilt)], axis=1)
    d = tb3.raycast_3d(origin, dirs, 10.0)
    np.testing.assert_allclose(d, 0.2 / np.cos(tilt), rtol=1e-12)


def test_raycast_3d_passes_over_a_pillar_and_hits_the_head(tb3: World) -> None:
    d = tb3.raycast_3d(np.array([0.5, 0.0, 0.6]), np.array([[1.0, 0.0, 0.0]]), 10.0)
    assert d[0] == pytest.approx(2.32682 - 0.5, abs=1e-9)
    d = tb3.raycast_3d(np.array([0.5, 0.0, 0.3]), np.array([[1.0, 0.0, 0.0]]), 10.0)
    assert d[0] == pytest.approx(0.45, abs=1e-12)


def test_raycast_3d_hits_caps_from_above(tb3: World) -> None:
    down = np.array([[0.0, 0.0, -1.0]])
    assert tb3.raycast_3d(np.array([1.1, 0.05, 1.0]), down, 5.0)[0] == pytest.approx(0.5)
    # Above the shell band (between the inner y = 2.54 and outer y = 2.8575 edges): its top at 0.97 m.
    assert tb3.raycast_3d(np.array([0.0, 2.7, 1.2]), down, 5.0)[0] == pytest.approx(0.23)
    # Above free floor next to the band: the floor.
    assert tb3.raycast_3d(np.array([0.0, 2.4, 1.2]), down, 5.0)[0] == pytest.approx(1.2)


def test_raycast_3d_sky_rays_miss(tb3: World) -> None:
    up = np.array([[0.0, 0.0, 1.0], [0.6, 0.0, 0.8]])
    d = tb3.raycast_3d(np.array([-2.0, -0.5, 0.2]), up, 100.0)
    assert np.all(np.isposinf(d))


def test_raycast_3d_horizontal_rays_agree_with_raycast_2d(tb3: World) -> None:
    angles = np.linspace(0.0, 2.0 * math.pi, 720, endpoint=False)
    dirs = np.stack([np.cos(angles), np.sin(angles), np.zeros_like(angles)], axis=1)
    for origin in ([-2.0, -0.5], [0.55, 0.55], [2.0, -0.3]):
        d2 = tb3.raycast_2d(np.array(origin), angles, SCAN_Z, 3.5)
        d3 = tb3.raycast_3d(np.array([*origin, SCAN_Z]), dirs, 3.5)
        np.testing.assert_allclose(d3, d2, rtol=0, atol=1e-12)


def test_raycast_3d_hits_lie_on_surfaces_and_bearing_groups_do_not_change_results(
    tb3: World, monkeypatch: pytest.MonkeyPatch
) -> None:
    rng = np.random.default_rng(7)
    dirs = rng.normal(size=(5000, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    for origin in ([-2.0, -0.5, 0.117], [0.55, -0.55, 0.3], [1.5, 1.5, 0.05]):
        o = np.array(origin)
        d = tb3.raycast_3d(o, dirs, 20.0)
        hit = np.isfinite(d)
        assert hit.mean() > 0.4
        points = o + d[hit, None] * dirs[hit]
        assert tb3.surface_distance_m(points).max() < 1e-9
        monkeypatch.setattr(world_module, "RAYS_PER_BEARING_GROUP", 10**9)  # one group
        d_one_group = tb3.raycast_3d(o, dirs, 20.0)
        monkeypatch.setattr(world_module, "RAYS_PER_BEARING_GROUP", 50)  # 64 groups
        d_many_groups = tb3.raycast_3d(o, dirs, 20.0)
        monkeypatch.undo()
        np.testing.assert_array_equal(d_one_group, d)
        np.testing.assert_array_equal(d_many_groups, d)


def test_clearance_on_known_points(tb3: World) -> None:
    spawn = np.array([-2.0, -0.5])
    pts = np.array([spawn, [0.0, 0.0], [0.0, 2.6], [3.0, 0.0], [6.0, 6.0], [0.5, 0.0]])
    c = tb3.clearance_m(pts)
    assert c[0] == pytest.approx(_inner_wall_distance(spawn), abs=1e-9)
    assert c[1] == pytest.approx(-0.15)  # at the centre of a pillar
    assert c[2] == pytest.approx(-0.06)  # inside the shell band
    assert c[3] < 0.0  # inside the head hexagon
    assert c[4] < 0.0  # outside the world
    assert c[5] == pytest.approx(0.35)  # between two pillars


def test_clearance_ignores_solids_outside_the_height_band(tb3: World) -> None:
    c = tb3.clearance_m(np.array([[0.0, 0.0]]), z_range_m=(0.6, 0.9))
    assert c[0] > 0.0  # the 0.5 m pillar is below the band


def test_surface_distance_3d_on_known_points(tb3: World) -> None:
    pts = np.array(
        [
            [0.5, 0.0, 0.2],  # floor 0.2 below; pillars 0.35 away
            [1.1, 0.0, 0.7],  # 0.2 above the pillar's top cap
            [1.35, 0.0, 0.3],  # 0.1 from the pillar's side
            [1.55, 0.0, 0.9],  # nearest is the pillar's top rim: hypot(0.3, 0.4)
            [1.1, 0.0, 0.5],  # on the cap
        ]
    )
    np.testing.assert_allclose(
        tb3.surface_distance_m(pts), [0.2, 0.2, 0.1, 0.5, 0.0], atol=1e-12
    )


def test_surface_distance_2d_on_known_points(tb3: World) -> None:
    spawn = np.array([[-2.0, -0.5]])
    assert tb3.surface_distance_2d_m(np.array([[0.5, 0.0]]))[0] == pytest.approx(0.35)
    assert tb3.surface_distance_2d_m(np.array([[0.0, 0.15]]))[0] == pytest.approx(0.0)
    # At 0.6 m only the wall and hexagons exist: the spawn point's nearest outline is the wall.
    d = tb3.surface_distance_2d_m(spawn, z_m=0.6)
    assert d[0] == pytest.approx(_inner_wall_distance(spawn[0]), abs=1e-9)


def test_to_json_round_trips(tb3: World, tmp_path) -> None:
    data = tb3.to_json()
    packaged = json.loads((world_module.DATA_DIR / "turtlebot3_world.json").read_text())
    assert data == packaged
    path = tmp_path / "copy.json"
    path.write_text(json.dumps(data))
    again = load_world(path)
    angles = np.linspace(0, 2 * math.pi, 90)
    np.testing.assert_array_equal(
        again.raycast_2d(np.array([-2.0, -0.5]), angles, SCAN_Z, 3.5),
        tb3.raycast_2d(np.array([-2.0, -0.5]), angles, SCAN_Z, 3.5),
    )


USER_WORLD = {
    "polygons": [
        # A 2 m square room wall with a 0.1 m thick band: outer 4x4, hole 3.8x3.8.
        {
            "name": "room",
            "vertices": [[-2, -2], [2, -2], [2, 2], [-2, 2]],
            "holes": [[[-1.9, -1.9], [-1.9, 1.9], [1.9, 1.9], [1.9, -1.9]]],
            "z": [0.0, 1.0],
        },
        # A low box (clockwise vertices on purpose).
        {"name": "box", "vertices": [[1, 0], [1, 1], [1.5, 1], [1.5, 0]], "z": [0.0, 0.2]},
    ],
    "cylinders": [{"name": "bin", "center": [-1.0, 0.0], "radius": 0.2, "z": [0.0, 0.8]}],
    "boundary": [[-1.9, -1.9], [1.9, -1.9], [1.9, 1.9], [-1.9, 1.9]],
    "spawn": {"x": 0.0, "y": 0.0, "yaw": 0.0},
}


def test_user_world_in_general_form(tmp_path) -> None:
    path = tmp_path / "lab.json"
    path.write_text(json.dumps(USER_WORLD))
    w = load_world(path)
    assert w.name == "lab"
    d = w.raycast_2d(np.zeros(2), np.array([0.0, math.pi / 2, math.pi]), 0.1, 10.0)
    np.testing.assert_allclose(d, [1.0, 1.9, 0.8])
    # Above the box's 0.2 m top the ray along +x reaches the room wall.
    d = w.raycast_2d(np.array([0.0, 0.5]), np.array([0.0]), 0.5, 10.0)
    assert d[0] == pytest.approx(1.9)
    c = w.clearance_m(np.array([[0.0, 0.0], [1.2, 0.5], [1.95, 0.0], [3.0, 0.0]]))
    assert c[0] == pytest.approx(0.8)
    assert c[1] < 0 and c[2] < 0 and c[3] < 0
    # Box top cap seen from above; the room band's top cap too.
    down = np.array([[0.0, 0.0, -1.0]])
    assert w.raycast_3d(np.array([1.2, 0.5, 0.5]), down, 5.0)[0] == pytest.approx(0.3)
    assert w.raycast_3d(np.array([1.95, 0.0, 1.5]), down, 5.0)[0] == pytest.approx(0.5)


@pytest.mark.parametrize(
    ("content", "message"),
    [
        ("{not json", "not valid JSON"),
        ("[1, 2]", "must hold a JSON object"),
        ('{"name": "x"}', "no obstacles"),
        ('{"cylinders": [{"center": [0, 0], "radius": -1, "z": [0, 1]}]}', "radius"),
        ('{"cylinders": [{"center": [0], "radius": 1, "z": [0, 1]}]}', "cylinders[0].center"),
        ('{"polygons": [{"vertices": [[0, 0], [1, 0]], "z": [0, 1]}]}', "at least 3"),
        ('{"polygons": [{"vertices": [[0, 0], [1, 0], [2, 0]], "z": [0, 1]}]}', "no area"),
        ('{"polygons": [{"vertices": [[0, 0], [1, 0], [1, 1]], "z": [1, 0]}]}', "zmin < zmax"),
        ('{"polygons": [{"vertices": [[0, 0], ["a", 0], [1, 1]], "z": [0, 1]}]}', "vertices[1]"),
        ('{"cylinders": [{"center": [0, 0], "radius": 1, "z": [0, 1]}]}', "spawn point"),
        ('{"cylinders": "no"}', "'cylinders' must be a list"),
        ('{"shell_wall": {"inner": [[0, 0], [1, 0], [1, 1]]}, "cylinders": []}', "shell_wall.outer"),
    ],
)
def test_bad_world_files_raise_one_line_errors(tmp_path, content: str, message: str) -> None:
    path = tmp_path / "bad.json"
    path.write_text(content)
    with pytest.raises(BagtoolsError) as info:
        load_world(path)
    assert message in info.value.problem
    assert info.value.path == str(path)
    assert "\n" not in str(info.value)


def test_missing_world_file_and_unknown_name(tmp_path) -> None:
    with pytest.raises(BagtoolsError, match="no such world file"):
        load_world(tmp_path / "nope.json")
    with pytest.raises(BagtoolsError, match="turtlebot3_world"):
        load_world("no_such_world")
    with pytest.raises(BagtoolsError, match="is a directory"):
        load_world(tmp_path)
