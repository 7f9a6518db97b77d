"""Localization (``bagtools localize``): simulated bags tracked in the map of another route, and the global search.

Simulated (always): a 120 s figure eight (seed 5) localized in the map of a
120 s lap (seed 1): the lap's ground-truth grid, and the map ``bagtools slam``
makes of it. Rows, each with its baseline from the same run:

- tracking speed, bag seconds per wall second of the localizer, against the
  laser odometry (ndt-odom's front end) on the same scans. Target >= 50x;
- APE against /ground_truth (the map's frame is the world's for the ground-truth
  grid; after SE(2) alignment for the SLAM map), against the simulator's
  AMCL-like localizer (its map -> odom) in the same bag. Target <= 1 cm;
- first fix within 2 s of bag time, at the place (5 cm), from 100 random starts
  with no initial pose, in each map (the SLAM map's frame fitted to the world's
  along the lap), against the global search's best place of the start scan
  alone. Target >= 95 of 100; with the starts the world's 180-degree twin
  explains as well over their first 2 s, which no localizer can fix by then;
- a kidnap (the scans jump 2.5 m mid-bag, the odometry does not): seconds from
  it to the recovered fix, against the seconds to the first fix at the start.
  Target <= 3 s.

The classic benchmark logs (``../shared/data/benchmark``, skipped when absent; not in ``--quick``): each
mapped by ``bagtools slam``, then localized in that map with no initial pose, with and without odometry;
the relations error against slam's own. Target: no worse than slam's. And the reverse: the log's first
half (by scans) mapped by ``slam``, its second half localized in that map, scored on the relations whose
two stamps both lie in the second half, against slam's trajectory of the whole log on the same relations,
and against slam of the second half alone in the same mode (the same scans: like for like);
its speed, whole and while tracking (the tracked scans' share of the bag over the localizer's time on them
and their share of the laser odometry's and the smoothing's: ACES's second half spends two thirds of its
scans where the first half's map explains nothing), against slam of the first half. Target >= 50x.

The global search (CSAIL, skipped when absent):

The map: the CSAIL building (``../shared/data/real/csail_scans``, skipped when
absent) mapped at 5 cm from its reference poses with returns up to 20 m (as
``slam`` maps), and four marks at the corners of a 100 m x 100 m square around
it, so that the search spans the issue's 100 m x 100 m. Twenty scans along the
path, each searched alone:

- seconds per scan (median), the whole search (coarse branch and bound with the
  distinct places, then each refined at 5 cm). Baseline in the same run: the
  branch and bound for the single best place over the same window (what the
  hypotheses cost on top). Target <= 2 s;
- the share of scans whose best hypothesis is the place (30 cm, 3 degrees of
  the reference), and the share where the place is among the hypotheses.
"""

from __future__ import annotations

import math
import tempfile
import time
from pathlib import Path

import numpy as np

from bench.common import Row, bag_halves

REAL_DIR = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "real"
SIDE_M = 100.0


def run(quick: bool) -> list[Row]:
    return _simulated_rows(quick) + _global_rows(quick) + ([] if quick else _benchmark_rows())


BENCHMARK_DIR = REAL_DIR.parent / "benchmark"


def _benchmark_rows() -> list[Row]:
    """Each classic benchmark log mapped by ``bagtools slam``, then localized in that map with no initial pose
    (with and without odometry): the relations error of the localization against slam's own (skipped when absent)."""
    from bagtools.commands.localize import LocalizeOptions, LocalizePipeline
    from bagtools.commands.slam import SlamOptions, SlamPipeline
    from bagtools.grid import write_nav2_map
    from bagtools.trajectory import read_relations
    from bagtools.trajectory.relations import relation_errors

    rows: list[Row] = []
    for log in ("aces", "intel", "fr079"):
        bag, relations = BENCHMARK_DIR / f"{log}.bag", BENCHMARK_DIR / f"{log}.relations"
        if not (bag.is_file() and relations.is_file()):
            continue
        reference = read_relations(relations)
        slam = SlamPipeline(bag, SlamOptions()).run()
        slam_error = relation_errors(reference, slam.trajectory)
        with tempfile.TemporaryDirectory(prefix="bench_localize_") as tmp:
            map_yaml = write_nav2_map(slam.grid, Path(tmp) / "map")
            for odometry in (True, False):
                result = LocalizePipeline(bag, map_yaml, LocalizeOptions(use_odometry=odometry)).run()
                error = relation_errors(reference, result.trajectory)
                mode = "with odometry" if odometry else "scans only"
                s = result.summary
                rows.append(Row("localize", f"relations error mean, {log} in its slam map, {mode} (max "
                                f"{error['trans_max_m']:.2f} m; {error['used']} of {len(reference)} scored; "
                                f"{s['scans_localized']} of {s['scans']} scans; lost {s['lost']})",
                                error["trans_mean_m"], "m", "slam's own trajectory", slam_error["trans_mean_m"], False,
                                "<= slam's"))
                rows.append(Row("localize", f"speed, {log}, {mode} (laser odometry and tracking)",
                                s["speed_x_real_time"], "x real time", "slam, whole command",
                                s["scans"] and slam.summary["timing_s"]["total"] and
                                (int(result.stamps_ns[-1]) - int(result.stamps_ns[0])) * 1e-9
                                / slam.summary["timing_s"]["total"], True, ">= 50"))
            rows += _reverse_rows(log, bag, reference, slam.trajectory, Path(tmp))
    return rows


def _reverse_rows(log: str, bag: Path, reference, slam_trajectory, tmp: Path) -> list[Row]:
    """The log's first half mapped by slam, its second half localized in that map (see the module docstring)."""
    from bagtools.grid import write_nav2_map
    from bagtools.commands.localize import LocalizeOptions, LocalizePipeline
    from bagtools.commands.slam import SlamOptions, SlamPipeline
    from bagtools.trajectory.relations import relation_errors

    first, second = bag_halves(bag, tmp)
    slam = SlamPipeline(first, SlamOptions()).run()
    map_yaml = write_nav2_map(slam.grid, tmp / f"{log}_first_half")
    slam_speed = (int(slam.trajectory.stamps_ns[-1]) - int(slam.trajectory.stamps_ns[0])) * 1e-9 / max(
        slam.summary["timing_s"]["total"], 1e-9)
    rows: list[Row] = []
    for odometry in (True, False):
        result = LocalizePipeline(second, map_yaml, LocalizeOptions(use_odometry=odometry)).run()
        half = reference.within(int(result.stamps_ns[0]), int(result.stamps_ns[-1]))
        error, theirs = relation_errors(half, result.trajectory), relation_errors(half, slam_trajectory)
        alone = relation_errors(half, SlamPipeline(second, SlamOptions(use_odometry=odometry)).run().trajectory)
        s = result.summary
        mode = "with odometry" if odometry else "scans only"
        rows.append(Row("localize", f"relations error mean, {log}'s second half in the slam map of its first half, "
                        f"{mode}, against slam of the same scans", error["trans_mean_m"], "m",
                        f"slam of the second half alone, {mode}", alone["trans_mean_m"], False,
                        "<= slam's (like for like)"))
        rows.append(Row("localize", f"relations error mean, {log}'s second half in the slam map of its first half, "
                        f"{mode} (max {error['trans_max_m']:.2f} m; {error['used']} of {len(half)} scored; "
                        f"{s['scans_by_state']['unmapped']} of {s['scans']} scans carried by the motion; lost "
                        f"{s['lost']}, corrected {s['corrected']}; {s['speed_x_real_time']:.0f}x real time)",
                        error["trans_mean_m"], "m", "slam's trajectory of the whole log", theirs["trans_mean_m"],
                        False, "<= slam's"))
        rows.append(Row("localize", f"speed, {log}'s second half, {mode} (laser odometry and tracking; "
                        f"{s['scans_by_state']['unmapped']} of {s['scans']} scans carried by the motion)",
                        s["speed_x_real_time"], "x real time", "slam of the first half, whole command", slam_speed,
                        True, ">= 50"))
        rows.append(Row("localize", f"speed while tracking, {log}'s second half, {mode} (the "
                        f"{s['scans_by_state']['tracking']} tracked scans' share of the bag over their time and "
                        "their share of the laser odometry's and the smoothing's)", s["speed_x_real_time_tracking"],
                        "x real time", "slam of the first half, whole command", slam_speed, True, ">= 50"))
    return rows


def scan_sequence(bag: Path):
    """A simulated bag's scans as the localizer takes them (base frame, recording order), its odometry poses
    (N, 3) and the ground truth (N, 3) at the scan stamps."""
    from bagtools.io import open_bag
    from bagtools.odometry.options import NdtOdomOptions
    from bagtools.odometry.pipeline import laser_dataset
    from bagtools.simtruth import read_ground_truth
    from bagtools.transforms import tform2pose

    dataset = laser_dataset(NdtOdomOptions())
    with open_bag(bag) as reader:
        inputs = dataset.read(reader)
        stamps, T, _ = read_ground_truth(reader)
    truth = tform2pose(T)[np.searchsorted(stamps, inputs.stamps_ns).clip(0, len(stamps) - 1)]
    return inputs, tform2pose(inputs.odometry[0]), truth


def _simulated_rows(quick: bool) -> list[Row]:
    from bagtools.grid import read_nav2_map, write_nav2_map
    from bagtools.commands.grid import GridMapOptions, GridMapPipeline
    from bagtools.commands.localize import LocalizePipeline, MapLocalizer
    from bagtools.commands.ndt_odom import run_front_end
    from bagtools.commands.slam import SlamOptions, SlamPipeline
    from bagtools.transforms import se2_between, se2_compose
    from bagtools_simulate.pipeline import SimConfig, simulate_bag

    duration = 60.0 if quick else 120.0
    rows: list[Row] = []
    with tempfile.TemporaryDirectory(prefix="bench_localize_") as tmp:
        root = Path(tmp)
        lap = simulate_bag(root / "lap", SimConfig(duration_s=duration, route="lap", seed=1, cloud=False)).path
        bag = simulate_bag(root / "figure8", SimConfig(duration_s=duration, route="figure8", seed=5, cloud=False)).path
        lap_slam = SlamPipeline(lap, SlamOptions()).run()
        maps = {"ground-truth grid": write_nav2_map(GridMapPipeline(lap, GridMapOptions(
                    poses="ground-truth", frame="map")).run().grid, root / "gt"),
                "SLAM map": write_nav2_map(lap_slam.grid, root / "slam")}
        t0 = time.perf_counter()
        front = run_front_end(bag)
        odometry_x = duration / (time.perf_counter() - t0)
        for name, map_yaml in maps.items():
            summary = LocalizePipeline(bag, map_yaml).run().summary
            where = f"{duration:.0f} s simulated figure eight in the {name} of a lap"
            rows.append(Row("localize", f"tracking speed, {where}", summary["speed_x_real_time"], "x real time",
                            "laser odometry (ndt-odom front end), same scans", odometry_x, True, ">= 50"))
            ape = "ape_m" if name == "ground-truth grid" else "ape_aligned_m"
            truth = summary["ground_truth"]
            rows.append(Row("localize", f"APE ({ape}) rmse, {where}", truth["ours"][ape]["rmse"], "m",
                            "the bag's AMCL-like localizer (map -> odom)", truth["bag_localizer"][ape]["rmse"], False,
                            "<= 0.01 m"))
        del front
        inputs, odom, truth = scan_sequence(bag)
        n_starts = 20 if quick else 100
        mirrored = np.column_stack([-truth[:, 0], -truth[:, 1], truth[:, 2] + math.pi])  # the world's twin
        for name, map_yaml in maps.items():
            to_map = _world_to_map(lap, lap_slam.trajectory) if name == "SLAM map" else np.zeros(3)
            rows += _start_rows(name, read_nav2_map(map_yaml), inputs, odom, se2_compose(to_map, truth),
                                se2_compose(to_map, mirrored), n_starts)
        nav2 = read_nav2_map(maps["ground-truth grid"])
        points = nav2.occupied_points()
        k0 = 120  # 24 s into the figure eight, 2.5 m from where it is 28 s later
        far = np.hypot(*(truth[:, :2] - truth[k0, :2]).T)
        j0 = int(np.flatnonzero((far > 2.4) & (np.arange(len(far)) > k0 + 20))[0])
        localizer = MapLocalizer(points, nav2.resolution_m)
        order = list(range(k0)) + list(range(j0, len(far)))
        for step, k in enumerate(order):
            o = odom[k] if k < k0 else se2_compose(odom[k0 - 1], se2_between(odom[j0], odom[k]))
            localizer.step(step, int(inputs.stamps_ns[k]), inputs.points_base(k), o)
        events = {e.kind: e.index for e in localizer.events}
        if "recovered" in events:
            recovery_s = (inputs.stamps_ns[order[events["recovered"]]] - inputs.stamps_ns[j0]) * 1e-9
            fix_s = (inputs.stamps_ns[events["fix"]] - inputs.stamps_ns[0]) * 1e-9
            rows.append(Row("localize", f"kidnap of {far[j0]:.1f} m mid-bag: seconds to the recovered fix", recovery_s,
                            "s", "seconds to the first fix at the bag's start", fix_s, False, "<= 3 s"))
    return rows


def _start_rows(name: str, nav2, inputs, odom: np.ndarray, truth: np.ndarray, twin: np.ndarray,
                n_starts: int) -> list[Row]:
    """From ``n_starts`` random scans of the figure eight, no initial pose, in the map ``nav2`` (``truth`` and
    its 180-degree ``twin`` (N, 3) in the map's frame): fixed within 2 s at the place (5 cm), still alike at 2 s
    with the place among the hypotheses, fixed wrong; and the starts the twin explains as well."""
    from bagtools.commands.localize import MapLocalizer
    from bagtools.commands.localize.settings import CONFIRM_MARGIN, TrackState

    points = nav2.occupied_points()
    starts = np.random.default_rng(11).choice(len(odom) - 20, size=n_starts, replace=False)
    fixed = first_right = twins = wrong = 0
    unfixed, alike = set(), set()
    for start in starts:
        localizer = MapLocalizer(points, nav2.resolution_m)
        deadline = inputs.stamps_ns[start] + 2_000_000_000
        if _twin_alike(localizer, inputs, truth, twin, start, deadline):
            alike.add(int(start))
        for step, k in enumerate(range(start, len(odom))):
            state = localizer.step(step, int(inputs.stamps_ns[k]), inputs.points_base(k), odom[k])
            if step == 0 and localizer.hypotheses:
                first_right += bool(np.hypot(*(localizer.hypotheses[0].pose[:2] - truth[k, :2])) < 0.05)
            at_place = [bool(np.hypot(*(h.pose[:2] - truth[k, :2])) < 0.05) for h in localizer.hypotheses]
            if state == TrackState.TRACKING:
                right = bool(np.hypot(*(localizer.poses[step][:2] - truth[k, :2])) < 0.05)
                fixed += right and inputs.stamps_ns[k] <= deadline
                wrong += not right
                break
            if inputs.stamps_ns[k] <= deadline < inputs.stamps_ns[min(k + 1, len(odom) - 1)]:
                twins += any(at_place) and len(at_place) > 1  # still alike at 2 s, the place among them
                unfixed.add(int(start))
    where = f"{n_starts} random starts, no initial pose, {name}"
    return [
        Row("localize", f"first fix within 2 s at the place (5 cm), {where}", fixed / n_starts, "share",
            "the start scan's best global-search place alone", first_right / n_starts, True, ">= 0.95"),
        Row("localize", f"not fixed at 2 s: places alike, the right one among them, {where}", twins / n_starts,
            "share", "fixes at a wrong place", wrong / n_starts, False, "fixes + these = 1"),
        Row("localize", f"starts whose first 2 s of scans the world's 180-degree twin explains as well (mean evidence "
            f"within the {CONFIRM_MARGIN} margin; {len(alike & unfixed)} of them not fixed at 2 s), {where}",
            len(alike) / n_starts, "share", "starts not fixed at 2 s", len(unfixed) / n_starts, False,
            "no localizer can fix these within 2 s")]


def _world_to_map(bag: Path, trajectory) -> np.ndarray:
    """The simulated world's frame in the frame of a map made from ``bag`` along ``trajectory`` (its base in the
    map): [x, y, theta], the best planar fit of the trajectory onto the bag's /ground_truth."""
    from bagtools.io import open_bag
    from bagtools.simtruth import read_ground_truth
    from bagtools.trajectory.evaluate import align_se2
    from bagtools.trajectory import Trajectory
    from bagtools.trajectory.metrics import associate

    with open_bag(bag) as reader:
        stamps, T, _ = read_ground_truth(reader)
    world, ours = associate(Trajectory(stamps, T), trajectory)
    R, t = align_se2(world.positions[:, :2], ours.positions[:, :2])
    return np.array([t[0], t[1], math.atan2(R[1, 0], R[0, 0])])


def _twin_alike(localizer, inputs, truth: np.ndarray, twin: np.ndarray, start: int, deadline: int) -> bool:
    """Does the TurtleBot3 world's 180-degree ``twin`` of the true pose (the world turned about its centre, which
    only the 'head' hexagon breaks; both (N, 3) in the map's frame) explain the scans from ``start`` to
    ``deadline`` as well as the true pose: mean evidence (score x share of beams not through walls, on the map)
    within the confirmation margin?"""
    from bagtools.commands.localize.settings import CONFIRM_MARGIN

    ours, theirs = [], []
    for k in range(start, len(truth)):
        if inputs.stamps_ns[k] > deadline:
            break
        points = inputs.points_base(k)
        for out, p in ((ours, truth[k]), (theirs, twin[k])):
            out.append(localizer.fine.score(points, p) * (1.0 - localizer.through_walls(points, p)))
    return float(np.mean(ours)) - float(np.mean(theirs)) < CONFIRM_MARGIN


def _global_rows(quick: bool) -> list[Row]:
    from bagtools.grid import read_nav2_map, write_nav2_map
    from bagtools.commands.grid import GridMapOptions, GridMapPipeline
    from bagtools.io import open_bag
    from bagtools.commands.localize import GlobalLocalizer
    from bagtools.commands.localize.global_search import REACH_M
    from bagtools.scan_matching import match_scans_grid, voxel_subsample
    from bagtools.commands.ndt_odom import run_front_end
    from bagtools.simtruth import read_ground_truth
    from bagtools.transforms import tform2pose

    bag = REAL_DIR / "csail_scans"
    if not bag.is_dir():
        return []
    options = GridMapOptions(poses="ground-truth", frame="map", resolution=20.0, max_range_m=20.0)
    grid = GridMapPipeline(bag, options).run().grid
    with tempfile.TemporaryDirectory(prefix="bench_localize_") as tmp:
        points = read_nav2_map(write_nav2_map(grid, Path(tmp) / "map")).occupied_points()
    centre = 0.5 * (points.min(axis=0) + points.max(axis=0))
    corners = centre + 0.5 * SIDE_M * np.array([[-1, -1], [-1, 1], [1, -1], [1, 1]])
    marks = np.concatenate([c + np.c_[np.arange(-0.5, 0.5, 0.05), np.zeros(20)] for c in corners])
    localizer = GlobalLocalizer(np.r_[points, marks])
    front = run_front_end(bag)
    with open_bag(bag) as reader:
        stamps, T_map_base, _ = read_ground_truth(reader)
    truth = tform2pose(T_map_base[np.searchsorted(stamps, front.front_end.stamps_ns())])
    picks = range(5, 400, 80 if quick else 20)
    search_s, best_s, best_right, among = [], [], 0, 0
    window = (float(localizer.half_extent[0]), float(localizer.half_extent[1]), math.pi)
    for k in picks:
        scan = front.front_end.steps[k].points_base
        t0 = time.perf_counter()
        hyps = localizer.search(scan)
        search_s.append(time.perf_counter() - t0)
        right = [np.hypot(*(h.pose[:2] - truth[k, :2])) < 0.3
                 and abs((h.pose[2] - truth[k, 2] + math.pi) % (2 * math.pi) - math.pi) < math.radians(3.0)
                 for h in hyps]
        best_right += bool(right and right[0])
        among += any(right)
        t0 = time.perf_counter()
        match_scans_grid(voxel_subsample(scan, localizer.coarse.resolution_m), localizer.coarse,
                         initial_pose=(localizer.centre[0], localizer.centre[1], 0.0), search_range=window,
                         angular_resolution_rad=localizer.coarse.resolution_m / REACH_M, min_score=0.3)
        best_s.append(time.perf_counter() - t0)
    n = len(picks)
    span = 2 * localizer.half_extent
    label = f"{span[0]:.0f} m x {span[1]:.0f} m map at 5 cm (CSAIL + corner marks), {n} scans"
    return [
        Row("global localization", f"seconds per scan, median, {label}", float(np.median(search_s)), "s",
            "best place only, same window", float(np.median(best_s)), False, "<= 2 s"),
        Row("global localization", f"scans whose best hypothesis is the place, {label}", best_right / n, "share",
            "scans whose hypotheses hold the place", among / n, True, "all held"),
    ]
