"""``bagtools localize``: a simulated bag localized in the map of another route, from no initial pose; lost and
recovered after a kidnap; a map that repeats itself; the command's files and its refusals."""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from bagtools.cli import main
from bagtools.grid import OccupancyGrid, read_nav2_map, write_nav2_map
from bagtools.commands.grid import GridMapOptions, GridMapPipeline
from bagtools.io import open_bag
from bagtools.commands.localize import LocalizeOptions, LocalizePipeline, MapLocalizer
from bagtools.commands.localize import tracker
from bagtools.commands.localize.settings import TrackState
from bagtools.transforms import se2_between, se2_compose
from bagtools_simulate.pipeline import SimConfig, simulate_bag
from bagtools_simulate.world import World
from bench.bench_localize import scan_sequence
from tests.localize.test_global_search import _room_scan, _room_walls


@pytest.fixture(scope="module")
def world(tmp_path_factory) -> dict[str, Path]:
    """A 60 s lap mapped from its ground truth (the map), and a 60 s figure eight of another seed (the bag)."""
    root = tmp_path_factory.mktemp("localize")
    lap = simulate_bag(root / "lap", SimConfig(duration_s=60.0, route="lap", seed=1, cloud=False)).path
    figure8 = simulate_bag(root / "figure8", SimConfig(duration_s=60.0, route="figure8", seed=5, cloud=False)).path
    grid = GridMapPipeline(lap, GridMapOptions(poses="ground-truth", frame="map")).run().grid
    return {"map": write_nav2_map(grid, root / "map"), "bag": figure8, "root": root}


@pytest.mark.parametrize("odometry", [True, False])
def test_a_bag_is_localized_in_the_map_of_another_route(world: dict, odometry: bool) -> None:
    result = LocalizePipeline(world["bag"], world["map"], LocalizeOptions(use_odometry=odometry)).run()
    s = result.summary
    assert s["first_fix"]["seconds_after_first_scan"] <= 2.0
    assert s["scans_localized"] == s["scans"] and s["lost"] == 0
    ours = s["ground_truth"]["ours"]["ape_m"]
    assert ours["rmse"] < 0.02 and ours["max"] < 0.05, ours  # the map's 5 cm cells bound it (bench: 1.0 cm)
    theirs = s["ground_truth"]["bag_localizer"]["ape_m"]
    assert ours["rmse"] < theirs["rmse"]  # the simulator's AMCL-like localizer: about 4 cm
    compared = s["bag_localizer"]
    assert compared["scans_compared"] > 250 and compared["parts"] == []
    assert (result.map_to_odom is not None) == odometry
    assert s["speed_x_real_time"] > 10  # the bench row holds the speed target; this only catches a stall
    t = s["timing_s"]  # where the time went: the parts add up, and tracking is the cheap part of it
    assert sum(t["localizer_by_state"].values()) <= t["localizer"]
    assert t["laser_odometry"] + t["localizer"] + t["smoothing"] <= t["total"]
    assert set(t["localizer_by_state"]) <= {k for k, n in s["scans_by_state"].items() if n}
    assert s["speed_x_real_time_tracking"] > s["speed_x_real_time"]  # the global search at the start is left out
    assert math.hypot(*s["map_offset_m"]) < 0.01, s["map_offset_m"]  # a laser that sees all round: no offset


def test_random_starts_are_fixed_within_two_seconds_or_said_alike_never_fixed_wrong(world: dict) -> None:
    """Twenty starts along the figure eight, no initial pose (the bench row runs a hundred). The TurtleBot3 world
    looks the same turned by 180 degrees from many places (the top and bottom walls): there the scans cannot tell
    the two places apart until the robot sees the sides, and the localizer must say so rather than guess."""
    inputs, odom, truth = scan_sequence(world["bag"])
    nav2 = read_nav2_map(world["map"])
    starts = np.random.default_rng(7).choice(len(odom) - 20, size=20, replace=False)
    fixed = alike = 0
    for start in starts:
        localizer = MapLocalizer(nav2.occupied_points(), nav2.resolution_m)
        for step, k in enumerate(range(start, len(odom))):
            state = localizer.step(step, int(inputs.stamps_ns[k]), inputs.points_base(k), odom[k])
            in_time = (inputs.stamps_ns[k] - inputs.stamps_ns[start]) * 1e-9 <= 2.0
            if state == TrackState.TRACKING:
                assert np.hypot(*(localizer.poses[step][:2] - truth[k, :2])) < 0.05, (start, step)  # never wrong
                fixed += in_time
                break
            if in_time and (inputs.stamps_ns[k + 1] - inputs.stamps_ns[start]) * 1e-9 > 2.0:
                alike += state == TrackState.AMBIGUOUS and any(np.hypot(*(h.pose[:2] - truth[k, :2])) < 0.05
                                                    for h in localizer.hypotheses)
    assert fixed + alike == len(starts) and fixed >= 10, (fixed, alike)


def test_a_kidnapped_robot_is_lost_and_recovered_within_three_seconds(world: dict) -> None:
    """Carried 2.5 m mid-bag: from scan 120 on the scans are those of a place 2.5 m away (the wheels saw
    nothing: the odometry continues from where it was)."""
    inputs, odom, truth = scan_sequence(world["bag"])
    nav2 = read_nav2_map(world["map"])
    k0 = 120
    far = np.hypot(*(truth[:, :2] - truth[k0, :2]).T)
    j0 = int(np.flatnonzero((far > 2.4) & (np.arange(len(far)) > k0 + 20))[0])
    localizer = MapLocalizer(nav2.occupied_points(), nav2.resolution_m)
    order = list(range(k0)) + list(range(j0, len(far)))
    for step, k in enumerate(order):
        o = odom[k] if k < k0 else se2_compose(odom[k0 - 1], se2_between(odom[j0], odom[k]))
        localizer.step(step, int(inputs.stamps_ns[k]), inputs.points_base(k), o)
    kinds = [(e.kind, e.index) for e in localizer.events]
    assert [k for k, _ in kinds] == ["fix", "lost", "recovered"], kinds
    lost, recovered = kinds[1][1], kinds[2][1]
    assert k0 <= lost and (inputs.stamps_ns[order[recovered]] - inputs.stamps_ns[j0]) * 1e-9 <= 3.0
    errors = [np.hypot(*(localizer.poses[s][:2] - truth[k][:2])) for s, k in enumerate(order) if s in localizer.poses]
    assert max(errors) < 0.05  # the scans between the kidnap and its detection are not kept


def test_a_map_that_repeats_itself_stays_ambiguous_until_the_scans_tell_the_places_apart() -> None:
    """A bare 10 m x 6 m room is the same turned by 180 degrees: no fix, however long the robot drives."""
    half = (5.0, 3.0)
    localizer = MapLocalizer(_room_walls(half), 0.05)
    states = []
    for k in range(15):
        pose = np.array([1.0 + 0.1 * k, 0.5, 0.3])
        states.append(localizer.step(k, k * 200_000_000, _room_scan(pose, half), pose))
    assert localizer.committed is None and states[-1] == TrackState.AMBIGUOUS and TrackState.CONFIRMING in states
    assert len(localizer.hypotheses) == 2


def test_the_command_writes_its_files_and_refuses_to_overwrite(world: dict, tmp_path: Path, capsys) -> None:
    out = tmp_path / "loc"
    argv = ["localize", str(world["bag"]), "--map", str(world["map"]), "--out", str(out)]
    with pytest.raises(SystemExit) as done:
        main(argv)
    assert done.value.code == 0
    names = {p.name for p in out.iterdir()}
    assert {"trajectory.tum", "map_to_odom.tum", "bag_localizer.tum", "ground_truth.tum", "localization.png",
            "localizer_comparison.png", "summary.json", "results.mcap"} <= names
    summary = json.loads((out / "summary.json").read_text())
    assert len(summary["per_scan"]["score"]) == summary["scans"] == len(summary["per_scan"]["state"])
    assert (out / "localization.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    with open_bag(out / "results.mcap") as bag:
        assert {"/map", "/trajectory", "/tf", "/scan", "/bag_localizer"} <= set(bag.topics)
    capsys.readouterr()
    with pytest.raises(SystemExit) as again:
        main(argv)
    err = capsys.readouterr().err
    assert again.value.code == 2 and "already exists" in err and "Traceback" not in err


def _without_map_to_odom_with_amcl_pose(bag: Path, out: Path, T_map_base, every: int = 3,
                                        dropped: tuple[str, ...] = ("odom",), frame: str = "map") -> Path:
    """``bag`` again without /tf's map -> odom (the transforms to the ``dropped`` children), with a
    geometry_msgs/PoseWithCovarianceStamped on /amcl_pose at every ``every``-th stamp of the Trajectory
    ``T_map_base``: as a bag recorded from AMCL's pose topic alone."""
    from rosbags.highlevel import AnyReader

    from bagtools.transforms import rotm2quat
    from tests.conftest import TYPESTORE, _header, write_bag

    T = TYPESTORE.types
    messages = []
    with AnyReader([bag]) as reader:
        for conn, t_ns, raw in reader.messages():
            msg = reader.deserialize(raw, conn.msgtype)
            if conn.topic == "/tf":
                msg.transforms = [ts for ts in msg.transforms if ts.child_frame_id not in dropped]
                if not msg.transforms:
                    continue
            messages.append((conn.topic, conn.msgtype, t_ns, msg))
    for stamp, pose in zip(T_map_base.stamps_ns[::every], T_map_base.poses[::every]):
        w, x, y, z = rotm2quat(pose[:3, :3])
        covariance = np.zeros(36)
        messages.append(("/amcl_pose", "geometry_msgs/msg/PoseWithCovarianceStamped", int(stamp) + 5_000_000,
                         T["geometry_msgs/msg/PoseWithCovarianceStamped"](
                             header=_header(int(stamp), frame), pose=T["geometry_msgs/msg/PoseWithCovariance"](
                                 pose=T["geometry_msgs/msg/Pose"](
                                     position=T["geometry_msgs/msg/Point"](x=pose[0, 3], y=pose[1, 3], z=pose[2, 3]),
                                     orientation=T["geometry_msgs/msg/Quaternion"](x=x, y=y, z=z, w=w)),
                                 covariance=covariance))))
    messages.sort(key=lambda m: m[2])
    return write_bag(out, messages)


def test_a_bag_with_only_amcl_pose_has_its_localizer_compared_through_it(world: dict, tmp_path: Path) -> None:
    """AMCL publishes its pose on /amcl_pose at each update, and map -> odom on /tf. A bag recorded without the
    latter is compared through the former, held between updates by the odometry, as AMCL holds its map -> odom."""
    with_tf = LocalizePipeline(world["bag"], world["map"]).run()
    assert with_tf.summary["bag_localizer"]["source"] == "/tf map -> base_footprint"
    bag = _without_map_to_odom_with_amcl_pose(world["bag"], tmp_path / "amcl", with_tf.bag_localizer)
    result = LocalizePipeline(bag, world["map"]).run()
    compared = result.summary["bag_localizer"]
    assert compared["source"].startswith("/amcl_pose")
    assert compared["scans_compared"] >= with_tf.summary["bag_localizer"]["scans_compared"] - 3
    # the same poses wherever the simulator's localizer made no update between two of the /amcl_pose samples
    # (its map -> odom held, as ours is); elsewhere apart by that update's correction, a few centimetres
    common, a, b = np.intersect1d(result.bag_localizer.stamps_ns, with_tf.bag_localizer.stamps_ns,
                                  return_indices=True)
    apart = np.linalg.norm(result.bag_localizer.poses[a, :2, 3] - with_tf.bag_localizer.poses[b, :2, 3], axis=1)
    assert common.size > 250 and np.median(apart) < 1e-6 and apart.max() < 0.3, (np.median(apart), apart.max())
    assert abs(compared["translation_m"]["mean"] - with_tf.summary["bag_localizer"]["translation_m"]["mean"]) < 0.01
    assert result.summary["ground_truth"]["bag_localizer"]["ape_m"]["rmse"] < 0.1
    # results.mcap's tree: the bag's own map -> odom keeps ours apart; without it, map -> odom ties the bag's robot in
    assert with_tf.map_to_odom_tf() is None
    odom_frame, map_to_odom = result.map_to_odom_tf()
    assert odom_frame == "odom" and len(map_to_odom) == len(result.trajectory)


def test_amcl_pose_in_another_frame_is_said(world: dict, tmp_path: Path) -> None:
    """An /amcl_pose not in the map's frame is compared as if it were, and said."""
    with_tf = LocalizePipeline(world["bag"], world["map"]).run()
    bag = _without_map_to_odom_with_amcl_pose(world["bag"], tmp_path / "amcl", with_tf.bag_localizer, frame="world")
    result = LocalizePipeline(bag, world["map"]).run()
    assert result.summary["bag_localizer"]["source"].startswith("/amcl_pose")
    assert any("/amcl_pose is in frame 'world'" in w for w in result.summary["warnings"]), result.summary["warnings"]


def test_amcl_pose_without_odometry_to_carry_it_is_said_not_compared(world: dict, tmp_path: Path) -> None:
    """Without odom -> base in tf, AMCL's pose cannot be carried between its updates: said, and not compared."""
    with_tf = LocalizePipeline(world["bag"], world["map"]).run()
    bag = _without_map_to_odom_with_amcl_pose(world["bag"], tmp_path / "amcl", with_tf.bag_localizer,
                                              dropped=("odom", "base_footprint"))
    result = LocalizePipeline(bag, world["map"], LocalizeOptions(use_odometry=False)).run()
    assert "bag_localizer" not in result.summary and result.bag_localizer is None
    assert any(w.startswith("/amcl_pose not compared") for w in result.summary["warnings"]), result.summary["warnings"]


def _bare_room_map(directory: Path) -> Path:
    directory.mkdir()
    image = np.full((120, 200), 254, dtype=np.uint8)
    image[0, :] = image[-1, :] = image[:, 0] = image[:, -1] = 0
    image[40:80, 90:92] = 0
    (directory / "room.pgm").write_bytes(b"P5\n200 120\n255\n" + image.tobytes())
    (directory / "room.yaml").write_text("image: room.pgm\nresolution: 0.05\norigin: [-5.0, -3.0, 0.0]\nnegate: 0\n"
                                         "occupied_thresh: 0.65\nfree_thresh: 0.196\n")
    return directory / "room.yaml"


@pytest.mark.parametrize("case", ["another place", "not a map", "no scans", "bad initial pose", "empty map"])
def test_bad_input_is_one_line_and_exit_2(world: dict, tmp_path: Path, capsys, case: str) -> None:
    bag, map_yaml, extra = str(world["bag"]), str(world["map"]), []
    if case == "another place":
        map_yaml = str(_bare_room_map(tmp_path / "room"))
    elif case == "not a map":
        map_yaml = str(world["bag"] / "metadata.yaml")
    elif case == "no scans":
        extra = ["--topic", "/odom"]
    elif case == "bad initial pose":
        extra = ["--initial-pose", "1,2"]
    else:
        (tmp_path / "e.pgm").write_bytes(b"P5\n4 3\n255\n" + bytes([254] * 12))
        (tmp_path / "e.yaml").write_text("image: e.pgm\nresolution: 0.05\norigin: [0, 0, 0]\nnegate: 0\n"
                                         "occupied_thresh: 0.65\nfree_thresh: 0.196\n")
        map_yaml = str(tmp_path / "e.yaml")
    with pytest.raises(SystemExit) as done:
        main(["localize", bag, "--map", map_yaml, "--out", str(tmp_path / "out"), *extra])
    err = capsys.readouterr().err.strip().splitlines()
    assert done.value.code == 2 and len(err) == 1 and err[0].startswith("bagtools: "), err
    assert not (tmp_path / "out").exists()
    expected = {"another place": "could be placed in the map", "not a map": "map YAML has no 'image'",
                "no scans": "expected sensor_msgs/msg/LaserScan", "bad initial pose": "X,Y,YAW",
                "empty map": "at least 5 occupied places"}[case]
    assert expected in err[0]


def test_an_initial_pose_skips_the_global_search(world: dict) -> None:
    inputs, _, truth = scan_sequence(world["bag"])
    start = truth[inputs.order[0]]
    guess = (float(start[0]) + 0.3, float(start[1]) - 0.2, float(start[2]) + 0.2)
    result = LocalizePipeline(world["bag"], world["map"], LocalizeOptions(initial_pose=guess)).run()
    assert result.summary["global_searches"] == 0 and result.summary["scans_localized"] == result.summary["scans"]
    assert result.summary["ground_truth"]["ours"]["ape_m"]["rmse"] < 0.02
    assert math.isclose(result.summary["first_fix"]["seconds_after_first_scan"], 0.8, abs_tol=0.25)


def test_a_fleet_is_localized_in_one_map(world: dict, tmp_path: Path, capsys) -> None:
    """``bagtools batch localize BAGS -- --map map.yaml``: a row per bag; a bad map is one error before any work."""
    bags = tmp_path / "bags"
    bags.mkdir()
    (bags / "figure8").symlink_to(world["bag"])
    with pytest.raises(SystemExit) as done:
        main(["batch", "localize", str(bags), "--out", str(tmp_path / "fleet"), "--workers", "1", "--",
              "--map", str(world["map"]), "--no-mcap"])
    assert done.value.code == 0, capsys.readouterr().err
    rows = (tmp_path / "fleet" / "fleet.csv").read_text().splitlines()
    header, row = rows[0].split(","), dict(zip(rows[0].split(","), rows[1].split(",")))
    assert "scans_localized" in header and row["status"] == "ok" and row["scans_localized"] == row["scans"]
    assert float(row["ape_m"]) < 0.02 and (tmp_path / "fleet" / "figure8" / "trajectory.tum").is_file()
    with pytest.raises(SystemExit) as bad:
        main(["batch", "localize", str(bags), "--out", str(tmp_path / "fleet2"), "--", "--map",
              str(tmp_path / "nowhere.yaml")])
    err = capsys.readouterr().err
    assert bad.value.code == 2 and "Traceback" not in err
    assert err.strip().splitlines()[-1].startswith("bagtools: ") and "nowhere.yaml: map YAML not found" in err


def _localizer_without_the_top_third(world: dict) -> MapLocalizer:
    """A localizer in the world's map with its top third (y > 0.8 m) made unknown: a part the map never saw."""
    import dataclasses

    nav2 = read_nav2_map(world["map"])
    occupancy = nav2.occupancy.copy()
    y = nav2.origin[1] + (occupancy.shape[0] - np.arange(occupancy.shape[0]) - 0.5) * nav2.resolution_m
    occupancy[y > 0.8, :] = -1
    cut = dataclasses.replace(nav2, occupancy=occupancy)
    return MapLocalizer(cut.occupied_points(), cut.resolution_m, known=cut.known)


def test_a_robot_off_the_map_is_carried_by_its_motion_not_lost(world: dict) -> None:
    """The map's top third made unknown (a part of the building the map never saw): the figure eight drives into
    it; there the scans match poorly, the motion carries the pose ('unmapped'), nothing is lost or jumps."""
    inputs, odom, truth = scan_sequence(world["bag"])
    localizer = _localizer_without_the_top_third(world)
    states = [localizer.step(step, int(inputs.stamps_ns[k]), inputs.points_base(k), odom[k])
              for step, k in enumerate(inputs.order)]
    assert TrackState.UNMAPPED in states and [e.kind for e in localizer.events] == ["fix"]
    errors = [np.hypot(*(localizer.poses[s][:2] - truth[k][:2])) for s, k in enumerate(inputs.order)
              if s in localizer.poses]
    assert len(errors) >= len(states) - 5 and max(errors) < 0.15, max(errors)


def test_where_the_map_lacks_walls_the_unbroken_laser_odometry_carries_the_pose_nothing_jumps(world: dict,
                                                                                             tmp_path: Path) -> None:
    """The map's top third keeps its free space but loses its walls (a part of the building seen from afar: known
    free, no walls). The scans there match the map poorly, and a look-alike elsewhere may match better; but the
    laser odometry matched every scan to the last, so the robot was not carried anywhere: no loss, no jump."""
    from bagtools.grid.mapio import pgm_bytes, read_pgm

    nav2 = read_nav2_map(world["map"])
    pixels = read_pgm(world["map"].parent / "map.pgm")
    y = nav2.origin[1] + (pixels.shape[0] - np.arange(pixels.shape[0]) - 0.5) * nav2.resolution_m
    top = pixels[y > 0.8, :]
    top[top == 0] = 254  # trinary: occupied (black) made free (white)
    pixels[y > 0.8, :] = top
    (tmp_path / "map.pgm").write_bytes(pgm_bytes(pixels))
    map_yaml = tmp_path / "map.yaml"
    map_yaml.write_text((world["map"].parent / "map.yaml").read_text())
    result = LocalizePipeline(world["bag"], map_yaml).run()
    s = result.summary
    assert s["lost"] == 0 and s["scans_localized"] == s["scans"], s["events"]
    assert s["scans_by_state"]["unmapped"] > 0
    ape = s["ground_truth"]["ours"]["ape_m"]
    assert ape["max"] < 0.15, ape


def test_a_kidnap_in_a_bag_breaks_the_laser_odometry_is_recovered_and_not_smoothed_over(world: dict,
                                                                                       monkeypatch) -> None:
    """The whole command on a bag whose scans jump 2.5 m at scan 120 (carried; the wheels saw nothing): the laser
    odometry cannot match the scan after the jump to the ones before, so the motion no longer bounds where the
    robot is: lost, searched for, recovered within 3 s, and the smoothing is cut there."""
    from bagtools.dataset import LaserDataset, ScanInputs

    inputs, _, truth = scan_sequence(world["bag"])
    k0 = 120
    far = np.hypot(*(truth[:, :2] - truth[k0, :2]).T)
    j0 = int(np.flatnonzero((far > 2.4) & (np.arange(len(far)) > k0 + 20))[0])
    keep = np.r_[np.arange(k0), np.arange(j0, len(far))]
    stamps = inputs.stamps_ns.copy()
    stamps[j0:] += stamps[k0] - stamps[j0]  # the bag goes on in time from the kidnap
    T, valid = inputs.odometry
    T = T.copy()
    T[j0:] = T[k0 - 1] @ np.linalg.inv(T[j0]) @ T[j0:]  # the wheels go on from where they were
    kidnapped = ScanInputs(stamps[keep], [inputs.points[k] for k in keep], np.arange(len(keep)),
                           (T[keep], valid[keep]), inputs.T_base_scan)
    read = LaserDataset.read
    monkeypatch.setattr(LaserDataset, "read", lambda self, bag: (read(self, bag), kidnapped)[1])
    result = LocalizePipeline(world["bag"], world["map"], LocalizeOptions()).run()
    kinds = [(e.kind, e.index) for e in result.events]
    assert [k for k, _ in kinds] == ["fix", "lost", "recovered"], kinds
    assert kinds[1][1] >= k0 and (stamps[keep][kinds[2][1]] - stamps[k0]) * 1e-9 <= 3.0
    known = np.isfinite(result.poses).all(axis=1)
    errors = np.hypot(*(result.poses[known, :2] - truth[keep][known, :2]).T)
    assert errors.max() < 0.05, errors.max()  # either side of the cut held by its own map matches


def test_smoothing_lowers_the_error_and_the_command_can_turn_it_off(world: dict, tmp_path: Path) -> None:
    """The path smoothed with the laser odometry is closer to the truth than each scan's own match (bench: 1.2 ->
    1.0 cm in the ground-truth grid); ``--no-smoothing`` gives the scans' own matches, as an online localizer has
    them."""
    smoothed = LocalizePipeline(world["bag"], world["map"]).run().summary
    with pytest.raises(SystemExit) as done:
        main(["localize", str(world["bag"]), "--map", str(world["map"]), "--out", str(tmp_path / "raw"),
              "--no-smoothing", "--no-mcap"])
    assert done.value.code == 0
    raw = json.loads((tmp_path / "raw" / "summary.json").read_text())
    assert smoothed["smoothed"] and not raw["smoothed"]
    ours, theirs = smoothed["ground_truth"]["ours"]["ape_m"], raw["ground_truth"]["ours"]["ape_m"]
    assert ours["rmse"] < theirs["rmse"], (ours, theirs)


def test_scans_match_the_walls_faces_not_the_occupied_cells_centres(tmp_path: Path) -> None:
    """A room mapped by raytracing a forward-looking laser (180 degrees, 1 cm range noise) from many poses: the
    beams clear the near part of the cells the walls cross, so the occupied cells' centres lie behind the walls
    the robot sees and a scan matched to them places it about 1.7 cm forward. Matched to the walls' faces (the
    borders of the occupied and the free cells), it is placed within a few millimetres."""
    rng = np.random.default_rng(1)
    half = (4.013, 3.031)  # walls off the cells' borders, as real walls are

    def front_scan(pose: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        points = _room_scan(pose, half, 360)
        angles = np.arctan2(points[:, 1], points[:, 0])
        ahead = np.abs(angles) <= math.pi / 2
        return angles[ahead], np.hypot(*points[ahead].T) + rng.normal(0.0, 0.01, np.count_nonzero(ahead))

    def random_pose() -> np.ndarray:
        return np.array([rng.uniform(-3.0, 3.0), rng.uniform(-2.2, 2.2), rng.uniform(-math.pi, math.pi)])

    grid = OccupancyGrid(10.0, 8.0, 20.0, (-5.0, -4.0))
    for _ in range(300):
        pose = random_pose()
        grid.insert_ray(pose, *front_scan(pose)[::-1], 8.0)
    nav2 = read_nav2_map(write_nav2_map(grid, tmp_path))
    forward = {}
    for name, faces in (("centres", None), ("faces", nav2.wall_faces())):
        localizer = MapLocalizer(nav2.occupied_points(), nav2.resolution_m, wall_faces=faces)
        ahead = []
        for _ in range(60):
            pose = random_pose()
            angles, ranges = front_scan(pose)
            found = localizer._refine(np.c_[ranges * np.cos(angles), ranges * np.sin(angles)], pose).pose
            ahead.append(se2_between(pose, found)[0])
        forward[name] = float(np.median(ahead))
    assert forward["centres"] > 0.01, forward  # the map's bias, which the test is about
    assert abs(forward["faces"]) < 0.004, forward


def test_a_motion_that_lags_along_a_corridor_is_corrected_by_the_map(tmp_path: Path, monkeypatch) -> None:
    """A 30 m corridor with pillars along its walls at irregular places, mapped by raytracing; the robot drives
    down it while its odometry (continuous, as a scan matcher's) says 10 % less along the corridor. NDT held by
    that motion stays near it (the walls do not fix the position along), scoring a little under the typical
    score; the window search around it finds the pillars where they are. Without that check the robot falls
    back 10 % of the way (over 2 m)."""
    def box(x0: float, y0: float, x1: float, y1: float) -> dict:
        return {"vertices": [[x0, y0], [x1, y0], [x1, y1], [x0, y1]], "z": [0.0, 1.0]}

    polygons = [box(-1.0, 1.0, 31.0, 1.2), box(-1.0, -1.2, 31.0, -1.0), box(-1.2, -1.2, -1.0, 1.2),
                box(31.0, -1.2, 31.2, 1.2)]
    for x in (2.0, 4.7, 8.1, 10.9, 13.2, 17.0, 19.4, 22.8, 25.1, 28.3):
        polygons += [box(x, 0.7, x + 0.2, 1.0), box(x + 1.3, -1.0, x + 1.5, -0.7)]
    world = World.from_dict({"name": "corridor", "polygons": polygons, "spawn": {"x": 0.0, "y": 0.0, "yaw": 0.0}})
    rng = np.random.default_rng(3)
    angles = np.linspace(-math.pi / 2, math.pi / 2, 181)

    def scan(pose: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        ranges = world.raycast_2d(pose[:2], pose[2] + angles, 0.2, 10.0)
        seen = np.isfinite(ranges)
        return angles[seen], ranges[seen] + rng.normal(0.0, 0.01, np.count_nonzero(seen))

    grid = OccupancyGrid(34.0, 4.0, 20.0, (-1.5, -2.0))
    for x in np.arange(0.0, 30.0, 0.2):
        for yaw in (0.0, math.pi):
            pose = np.array([x, rng.uniform(-0.3, 0.3), yaw + rng.normal(0.0, 0.05)])
            angles_seen, ranges = scan(pose)
            grid.insert_ray(pose, ranges, angles_seen, 10.0)
    nav2 = read_nav2_map(write_nav2_map(grid, tmp_path))
    truth = [np.array([0.5 + 0.1 * k, 0.2 * math.sin(0.05 * k), 0.0]) for k in range(250)]

    def run() -> np.ndarray:
        localizer = MapLocalizer(nav2.occupied_points(), nav2.resolution_m, initial_pose=truth[0], known=nav2.known,
                                 wall_faces=nav2.wall_faces())
        odom = np.zeros(3)
        for k, pose in enumerate(truth):
            if k:
                odom = odom + (pose - truth[k - 1]) * [0.9, 1.0, 1.0]
            angles_seen, ranges = scan(pose)
            localizer.step(k, k * 100_000_000, np.c_[ranges * np.cos(angles_seen), ranges * np.sin(angles_seen)],
                           odom, continuous=k > 0)
        assert sorted(localizer.poses) == list(range(len(truth)))  # all placed (the first ones once confirmed)
        return np.array([np.hypot(*(localizer.poses[k][:2] - pose[:2])) for k, pose in enumerate(truth)])

    errors = run()
    assert errors.max() < 0.3 and errors[-1] < 0.15, errors
    monkeypatch.setattr(tracker, "CHECK_RATIO", 0.0)  # no check: NDT held by the motion is taken as it is
    assert run()[-1] > 1.0


def _with_and_without_floors(run: Callable[[], MapLocalizer], monkeypatch,
                             window: tuple[float, float, float] | None = None) -> list[tuple[MapLocalizer, int]]:
    """``run()`` twice: as it is, then with the tracker's searches (of ``window`` only, when given) at
    ``min_score`` 0 (searched in full); each run's localizer and the nodes its searches scored."""
    searched = tracker.match_scans_grid
    runs = []
    for floored in (True, False):
        work: list[int] = []

        def search(*args, floored=floored, work=work, **kwargs):
            if not floored and (window is None or tuple(kwargs["search_range"]) == window):
                kwargs["min_score"] = 0.0
            found = searched(*args, **kwargs)
            work.append(found.n_evaluated)
            return found

        monkeypatch.setattr(tracker, "match_scans_grid", search)
        runs.append((run(), sum(work)))
    return runs


def test_a_wide_search_only_looks_for_poses_the_motion_cannot_explain(world: dict, monkeypatch) -> None:
    """The wheels jump 1 m at scan 150 (a glitch; the robot did not move): NDT and the window around the odometry's
    pose find nothing, and the wide window finds the robot where it was, at once. That search drops every pose
    scoring under what a pose the motion cannot explain needs: the same poses as searching it all, for less work."""
    inputs, odom, truth = scan_sequence(world["bag"])
    nav2 = read_nav2_map(world["map"])
    k0 = 150
    jump = np.array([1.0, 0.0, 0.0])

    def run() -> MapLocalizer:
        localizer = MapLocalizer(nav2.occupied_points(), nav2.resolution_m)
        for step, k in enumerate(inputs.order):
            o = odom[k] if step < k0 else se2_compose(odom[k], jump)
            localizer.step(step, int(inputs.stamps_ns[k]), inputs.points_base(k), o)
        return localizer

    (floored, work), (unfloored, all_work) = _with_and_without_floors(run, monkeypatch)
    kinds = [(e.kind, e.index) for e in floored.events]
    assert kinds[0][0] == "fix" and ("lost", k0) in kinds and ("recovered", k0) in kinds, kinds
    placed = floored.poses
    errors = [np.hypot(*(placed[s][:2] - truth[k][:2])) for s, k in enumerate(inputs.order) if s in placed]
    assert max(errors) < 0.05, max(errors)
    assert floored.poses.keys() == unfloored.poses.keys()
    assert all(np.allclose(floored.poses[s], unfloored.poses[s], atol=1e-9) for s in floored.poses)
    assert work < all_work, (work, all_work)


def test_a_robot_carried_off_the_map_is_searched_only_for_what_it_would_take(world: dict, monkeypatch) -> None:
    """The map's top third made unknown: the figure eight drives into it, carried by its motion, searched around
    every fifth scan. The search around the motion's pose (WINDOW) is taken there only when it matches at least
    poorly: its branch and bound drops every pose under that. The same poses as searching it all, for less work."""
    inputs, odom, _ = scan_sequence(world["bag"])

    def run() -> MapLocalizer:
        localizer = _localizer_without_the_top_third(world)
        for step, k in enumerate(inputs.order):
            localizer.step(step, int(inputs.stamps_ns[k]), inputs.points_base(k), odom[k], continuous=step > 0)
        return localizer

    (floored, work), (unfloored, all_work) = _with_and_without_floors(run, monkeypatch, tracker.WINDOW)
    assert TrackState.UNMAPPED in floored.states
    assert floored.poses.keys() == unfloored.poses.keys() and floored.states == unfloored.states
    assert all(np.allclose(floored.poses[s], unfloored.poses[s], atol=1e-9) for s in floored.poses)
    assert work < all_work, (work, all_work)


def test_a_robot_standing_still_off_the_map_is_not_searched_for_again_and_again(world: dict, monkeypatch) -> None:
    """The map's top third made unknown; the figure eight drives into it and stops there for 60 scans (the same
    scan, the laser odometry continuous). A search around the motion's pose that found nothing is not repeated
    until the scan has moved by a map cell: standing still it would see the same. Moving on, it searches again."""
    inputs, odom, _ = scan_sequence(world["bag"])
    searches = []
    searched = tracker.match_scans_grid
    monkeypatch.setattr(tracker, "match_scans_grid", lambda *a, **k: (searches.append(1), searched(*a, **k))[1])
    localizer = _localizer_without_the_top_third(world)
    step, stamp = 0, 0
    states = []
    for k in inputs.order:
        stamp = int(inputs.stamps_ns[k])
        states.append(localizer.step(step, stamp, inputs.points_base(k), odom[k], continuous=step > 0))
        step += 1
        if states[-5:] == [TrackState.UNMAPPED] * 5:
            break
    assert states[-1] == TrackState.UNMAPPED and localizer.committed is not None
    before, pose = len(searches), localizer.committed.pose.copy()
    for _ in range(60):  # standing still where the map knows nothing
        stamp += 100_000_000
        assert localizer.step(step, stamp, inputs.points_base(k), odom[k], continuous=True) == TrackState.UNMAPPED
        step += 1
    assert len(searches) - before <= 2, len(searches) - before  # without: 24 (a search every fifth scan, 2 windows)
    assert np.allclose(localizer.committed.pose, pose)
    later = [j for j in inputs.order if inputs.stamps_ns[j] > inputs.stamps_ns[k]][:20]
    before = len(searches)
    for j in later:  # driving on, deeper into what the map does not know
        stamp += 100_000_000
        localizer.step(step, stamp, inputs.points_base(j), odom[j], continuous=True)
        step += 1
    assert len(searches) > before


def _rescaled(map_yaml: Path, factor: float, out: Path) -> Path:
    """The same image with its YAML's resolution multiplied by ``factor`` (a map at the wrong scale)."""
    out.mkdir(parents=True, exist_ok=True)
    text = map_yaml.read_text()
    image = next(line.split(":", 1)[1].strip() for line in text.splitlines() if line.startswith("image:"))
    (out / Path(image).name).write_bytes((map_yaml.parent / image).read_bytes())
    resolution = next(float(line.split(":", 1)[1]) for line in text.splitlines() if line.startswith("resolution:"))
    lines = [f"resolution: {resolution * factor}" if line.startswith("resolution:") else
             f"image: {Path(image).name}" if line.startswith("image:") else line for line in text.splitlines()]
    (out / "map.yaml").write_text("\n".join(lines) + "\n")
    return out / "map.yaml"


@pytest.mark.parametrize("wrong", ["twice the scale", "a rectangular room"])
def test_a_map_the_scans_cannot_fit_is_refused(world: dict, tmp_path: Path, capsys, wrong: str) -> None:
    """Placed somewhere in a map of another place or scale, the scans fit it far worse than they fit each other
    (the laser odometry's neighbours): refused in one line, not '101 of 101 localized' metres off (#42)."""
    if wrong == "twice the scale":
        map_yaml = _rescaled(Path(world["map"]), 2.0, tmp_path / "scaled")
    else:
        map_yaml = _rectangle_map(tmp_path / "rect", 5.0, 3.5)
    with pytest.raises(SystemExit) as done:
        main(["localize", str(world["bag"]), "--map", str(map_yaml), "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err.strip().splitlines()
    assert done.value.code == 2 and len(err) == 1, err
    assert "do not fit the map" in err[0] or "could be placed in the map" in err[0], err[0]
    assert not (tmp_path / "out").exists()


def test_the_right_map_fits_as_well_as_the_scans_fit_each_other(world: dict) -> None:
    fit = LocalizePipeline(world["bag"], world["map"]).run().summary["map_fit"]
    assert fit["ratio"] > 0.8 and fit["scans"] >= 20, fit


def _rectangle_map(directory: Path, width_m: float, height_m: float) -> Path:
    """A bare rectangular room of ``width_m`` x ``height_m`` (walls only, free inside), 5 cm cells, centred on 0."""
    directory.mkdir()
    cols, rows = int(round(width_m / 0.05)) + 20, int(round(height_m / 0.05)) + 20
    image = np.full((rows, cols), 205, dtype=np.uint8)
    image[10:-10, 10:-10] = 254
    image[10, 10:-10] = image[-11, 10:-10] = image[10:-10, 10] = image[10:-10, -11] = 0
    (directory / "rect.pgm").write_bytes(f"P5\n{cols} {rows}\n255\n".encode() + image.tobytes())
    (directory / "rect.yaml").write_text(f"image: rect.pgm\nresolution: 0.05\norigin: [{-cols * 0.025}, "
                                         f"{-rows * 0.025}, 0.0]\nnegate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n")
    return directory / "rect.yaml"


def test_a_huge_mostly_unknown_map_is_drawn_from_its_known_part_in_place(world: dict, tmp_path: Path) -> None:
    """The picture's and results.mcap's grid of a 4000 x 4000 image holding the map in one corner is cut to the
    known cells (#42: a 12000 x 12000 map took 35 s and 5 GB): every occupied cell keeps its world position."""
    from bagtools.commands.localize.writer import map_grid

    small = read_nav2_map(world["map"])
    pixels = np.full((4000, 4000), 205, dtype=np.uint8)
    rows, cols = small.pixels.shape
    pixels[4000 - rows - 7:4000 - 7, 11:11 + cols] = small.pixels  # 7 rows above the bottom, 11 columns in
    (tmp_path / "big.pgm").write_bytes(b"P5\n4000 4000\n255\n" + pixels.tobytes())
    x0, y0 = small.origin[0] - 11 * small.resolution_m, small.origin[1] - 7 * small.resolution_m
    (tmp_path / "big.yaml").write_text(f"image: big.pgm\nmode: trinary\nresolution: {small.resolution_m}\n"
                                       f"origin: [{x0}, {y0}, 0.0]\nnegate: 0\noccupied_thresh: 0.65\n"
                                       "free_thresh: 0.196\n")
    big_grid, small_grid = map_grid(read_nav2_map(tmp_path / "big.yaml")), map_grid(small)
    assert max(big_grid.grid_size) < 2 * max(small_grid.grid_size)

    def occupied_xy(grid) -> np.ndarray:
        p = grid.occupancy_matrix("probability")
        xy = grid.grid2world(np.argwhere(p > 0.9))
        return xy[np.lexsort(xy.T[::-1])]

    np.testing.assert_allclose(occupied_xy(big_grid), occupied_xy(small_grid), atol=1e-6)
