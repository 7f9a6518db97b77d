"""Writing a localization run's files together, atomically (all or nothing, see :mod:`bagtools.outputs`)."""

from __future__ import annotations

import io
import json
from pathlib import Path

import numpy as np

from bagtools.grid import Nav2Map, OccupancyGrid
from bagtools.commands.localize.pipeline import MAP_FRAME, PART_DEG, PART_M, LocalizeResult
from bagtools.outputs import OutputDir
from bagtools.results import RESULTS_MCAP, Markers, ResultsBag, run_outputs
from bagtools.grid.render import render_slam_map_png
from bagtools.trajectory import tum_text

#: Every file the command may write (any existing one is refused without --force).
LOCALIZE_FILES = ["trajectory.tum", "map_to_odom.tum", "bag_localizer.tum", "ground_truth.tum", "localization.png",
                  "localizer_comparison.png", "summary.json", RESULTS_MCAP]


def write_localize(result: LocalizeResult, out_dir: str | Path, force: bool = False, mcap: bool = True) -> list[Path]:
    """Write the run into ``out_dir``; returns the paths written.

    trajectory.tum (the base in the map frame at every localized scan),
    map_to_odom.tum (the correction, with odometry), bag_localizer.tum and
    localizer_comparison.png (when the bag has its own map -> base),
    ground_truth.tum (simulated bags), localization.png, summary.json, and with
    ``mcap`` results.mcap (the map, the paths, /tf and the scans).
    """
    written: list[str] = []
    with OutputDir(out_dir, run_outputs(LOCALIZE_FILES, mcap), force) as staged:
        files = {"trajectory.tum": (result.trajectory, MAP_FRAME, result.base_frame),
                 "map_to_odom.tum": (result.map_to_odom, MAP_FRAME, "odom"),
                 "bag_localizer.tum": (result.bag_localizer, MAP_FRAME, result.base_frame),
                 "ground_truth.tum": (result.ground_truth, MAP_FRAME, result.base_frame)}
        for name, (traj, frame, body) in files.items():
            if traj is not None:
                (staged / name).write_text(tum_text(traj, frame, body))
                written.append(name)
        (staged / "localization.png").write_bytes(render_localization_png(result))
        written.append("localization.png")
        if result.bag_localizer is not None and result.summary.get("bag_localizer", {}).get("scans_compared"):
            (staged / "localizer_comparison.png").write_bytes(render_comparison_png(result))
            written.append("localizer_comparison.png")
        (staged / "summary.json").write_text(json.dumps(result.summary, indent=2) + "\n")
        written.append("summary.json")
        if mcap:
            with ResultsBag(staged / RESULTS_MCAP, namespace="localize") as bag:
                write_localize_results(bag, result)
            written.append(RESULTS_MCAP)
    return [Path(out_dir) / name for name in written]


def map_grid(nav2_map: Nav2Map) -> OccupancyGrid:
    """The nav2 map as an :class:`OccupancyGrid` for pictures and results.mcap (occupied 1, free 0, unknown 0.5;
    the origin's yaw, which map_server applies, is not drawn), cut to its known cells and a cell around them: a
    12000 x 12000 image of a building in one corner costs what the building does."""
    ternary = nav2_map.ternary()
    known = ternary != -1
    rows, cols = np.flatnonzero(known.any(axis=1)), np.flatnonzero(known.any(axis=0))
    del known
    height = ternary.shape[0]
    if rows.size:  # else the whole (unknown) image
        r0, r1 = max(int(rows[0]) - 1, 0), min(int(rows[-1]) + 1, height - 1)
        c0, c1 = max(int(cols[0]) - 1, 0), min(int(cols[-1]) + 1, ternary.shape[1] - 1)
        ternary = ternary[r0:r1 + 1, c0:c1 + 1]
    else:
        r1, c0 = height - 1, 0
    res = nav2_map.resolution_m
    origin = np.asarray(nav2_map.origin[:2], dtype=np.float64) + np.array([c0 * res, (height - 1 - r1) * res])
    probability = np.array([0.5, 0.0, 1.0], dtype=np.float32)[ternary.astype(np.intp) + 1]  # unknown, free, occupied
    return OccupancyGrid.from_probabilities(probability, 1.0 / res, origin)


def render_localization_png(result: LocalizeResult) -> bytes:
    """The map with the localized path (broken where unknown), the first fix, and where the robot was lost
    and recovered."""
    s = result.summary
    marks = [(label, np.array([e.pose[:2] for e in result.events if e.kind == kind]).reshape(-1, 2), marker, colour)
             for kind, label, marker, colour in (("fix", "first fix", "*", "tab:green"), ("lost", "lost", "x", "red"),
                                                 ("recovered", "recovered", "o", "tab:orange"),
                                                 ("corrected", "corrected", "+", "tab:purple"))]
    title = (f"{s.get('topic', '')}: {s.get('scans_localized', 0)} of {s.get('scans', 0)} scans localized, "
             f"lost {s.get('lost', 0)}, recovered {s.get('recovered', 0)}, corrected {s.get('corrected', 0)}")
    return render_slam_map_png(map_grid(result.nav2_map), result.poses[:, :2], np.zeros((0, 2, 2)), title, marks=marks)


def render_comparison_png(result: LocalizeResult) -> bytes:
    """Ours against the bag's own localizer over time: the translation and heading between them."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    diff = result.summary["bag_localizer"]["difference"]
    t = (np.asarray(diff["stamp_ns"], dtype=np.int64) - int(result.stamps_ns[0])) * 1e-9
    fig = Figure(figsize=(10, 5), dpi=100)
    FigureCanvasAgg(fig)
    top, bottom = fig.subplots(2, 1, sharex=True)
    top.plot(t, diff["translation_m"], color="tab:blue")
    top.axhline(PART_M, color="red", linestyle="--", linewidth=0.8, label=f"{PART_M} m")
    top.set_ylabel("translation [m]")
    top.legend(loc="upper right", fontsize="small")
    bottom.plot(t, diff["heading_deg"], color="tab:purple")
    bottom.axhline(PART_DEG, color="red", linestyle="--", linewidth=0.8, label=f"{PART_DEG} deg")
    bottom.set_ylabel("heading [deg]")
    bottom.set_xlabel("time since the first scan [s]")
    bottom.legend(loc="upper right", fontsize="small")
    top.set_title("ours against the bag's own localizer (map -> base)")
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    return buf.getvalue()


def write_localize_results(bag: ResultsBag, result: LocalizeResult) -> None:
    """In the map frame: /map, /trajectory, /bag_localizer and /ground_truth as paths, /tf (map -> base at each
    localized scan) with the laser on the base, the scans at their stamps, and the events as markers. When the bag's
    odometry frame has no parent, /tf also carries map -> odom (:meth:`LocalizeResult.map_to_odom_tf`)."""
    bag.occupancy_grid(map_grid(result.nav2_map), MAP_FRAME)
    for topic, traj in (("/trajectory", result.trajectory), ("/bag_localizer", result.bag_localizer),
                        ("/ground_truth", result.ground_truth)):
        if traj is not None and len(traj):
            bag.path(topic, traj.stamps_ns, traj.poses, MAP_FRAME)
    if len(result.trajectory):
        sensors = {result.scan_frame: result.T_base_scan} if result.scan_frame and result.scan_frame != result.base_frame else {}
        bag.robot(MAP_FRAME, result.base_frame, result.trajectory.stamps_ns, result.trajectory.poses, sensors)
    ties = result.map_to_odom_tf()
    if ties is not None:
        odom_frame, map_to_odom = ties
        bag.tf(MAP_FRAME, odom_frame, map_to_odom.stamps_ns, map_to_odom.poses)
    if result.scans:
        bag.scans(result.summary.get("topic", "/scan"), result.scans)
    for kind, rgba in (("lost", (1.0, 0.1, 0.1, 1.0)), ("recovered", (1.0, 0.6, 0.0, 1.0)), ("fix", (0.1, 0.8, 0.1, 1.0)),
                       ("corrected", (0.6, 0.2, 0.8, 1.0))):
        xy = np.array([e.pose[:2] for e in result.events if e.kind == kind]).reshape(-1, 2)
        if len(xy):
            bag.markers(f"/{kind}", MAP_FRAME, [Markers(kind, "sphere_list", np.c_[xy, np.zeros(len(xy))], rgba, 0.2)])
