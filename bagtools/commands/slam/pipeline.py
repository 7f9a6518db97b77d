"""Laser SLAM of one bag: front end, loop closure and pose graph, every scan's pose, the map, the errors.

    SlamPipeline(bag, options).run()
        _check_bag()        the scan topic is there (one-line error before any work)
        _front_end()        laser odometry: every scan registered, keyframes chained (bagtools.odometry.pipeline.run_front_end)
        _back_end()         keyframes as nodes, loop search, GTSAM optimization (bagtools.pose_graph.backend)
        _trajectories()     every scan's pose: a keyframe's optimized pose, or its keyframe's composed with
                            its match; the front end's alone
        _map()              the occupancy grid at the optimized poses (bagtools.grid.pipeline)
        _evaluate()         against the bag's /ground_truth (as the front end reads it): APE, RPE, aligned APE,
                            gap errors; against a .relations file when given (Kuemmerle et al.'s metric)
        _summary()

Frames. The front end gives poses of the robot base in its odometry frame (the
wheel odometry's when the bag has odometry and ``use_odometry``, else the first
scan's base pose is the origin). The map frame of SLAM is that frame as it
was at the first scan: the first keyframe is held at its front-end pose, so
``trajectory.tum`` and ``odometry.tum`` start at the same pose and part as the
loops correct the drift. ``ground_truth.tum`` is the bag's ``/ground_truth``
moved into the map frame so that it starts at the first scan's pose too (as
``evo --align_origin``; the front end's ground truth, as ``ndt-odom`` writes
it): evo compares the files directly.

Measured (one shared core, default options; bench/bench_slam.py): the CSAIL
log with odometry (396 s, 406 scans, 380 m) in 12-15 s: APE after alignment
11 cm (laser odometry alone 62 cm), mean error of the motion over 20 scans
11.0 cm (12.8 cm), 176 loops accepted of 319 candidates; a simulated figure
eight with high odometry noise (600 s): 3 mm (9 mm), the map 1.0 precision and
0.96 recall against the true world, in 17 s; 13 500 simulated scans (2700 s)
in 130 s.
"""

from __future__ import annotations

import math
import time
from collections import Counter
from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from bagtools.dataset import ScanClock, require_topic
from bagtools.errors import BagtoolsError
from bagtools.grid import OccupancyGrid
from bagtools.grid.options import MAX_RESOLUTION, MIN_RESOLUTION, GridMapOptions, map_cell_size
from bagtools.grid.pipeline import GridMapPipeline
from bagtools.io import LASERSCAN_TYPES, open_bag
from bagtools.odometry.options import NdtOdomOptions
from bagtools.odometry.pipeline import NdtOdomResult, run_front_end
from bagtools.odometry.steps import FrontEndRun
from bagtools.pose_graph.backend import BackEndOptions, BackEndResult, build_pose_graph
from bagtools.pose_graph.loops import LoopOptions, LoopOutcome
from bagtools.trajectory import Relations, Trajectory, read_relations, relation_errors
from bagtools.trajectory.evaluate import trajectory_errors
from bagtools.transforms import pose2tform, se2_between, se2_compose, wrap_to_pi

#: The frame name the map is built in by the grid pipeline: not the bag's "map" (see the module docstring).
SLAM_FRAME = "slam_map"


#: Returns farther than this only clear free space in the map, unless --max-range says otherwise (metres): a
#: no-return beam of a long-range laser (CSAIL's 81.9 m) would otherwise sweep the whole map.
MAP_MAX_RANGE_M = 20.0


@dataclass(frozen=True)
class SlamOptions:
    """How to run SLAM (the CLI's options).

    ``topic``: LaserScan topic. ``use_odometry``: let the front end use the
    bag's wheel odometry as its first guess (False: scans only).
    ``resolution_m``: side of a map cell, metres (the ``grid`` command's
    ``--resolution`` is cells per metre instead). ``max_range_m``: returns
    farther than this are not used, neither in the map (they only clear free
    space up to it) nor for loop closure (None: MAP_MAX_RANGE_M, 20 m, in the
    map, as slam_toolbox's max_laser_range; ``loop_max_range_m`` for loops). ``loop_search_radius_m``: how far apart
    two keyframes may be (beyond their estimated uncertainty) to be matched for
    a loop. ``loop_closure``: False keeps the front end's trajectory (the graph
    is the odometry chain). ``loop_min_score``: correlative score (in [0, 1])
    a loop match needs. ``keep_scans``: keep the input scans in the result
    (``SlamResult.front_end.scans``), for results.mcap. ``relations``: a
    ``.relations`` file of the log (Kümmerle et al. 2009, the classic
    benchmarks' ground truth) to score both trajectories with
    (:mod:`bagtools.trajectory.relations`). ``scan_frame_offset``: (x m, y m,
    yaw rad) of the laser on the robot base, overriding (or standing in for)
    tf, for the front end and the map alike.
    """

    topic: str = "/scan"
    use_odometry: bool = True
    resolution_m: float = 0.05
    max_range_m: float | None = None
    loop_search_radius_m: float = 5.0
    loop_closure: bool = True
    loop_min_score: float = 0.5
    loop_max_range_m: float = 20.0
    loop_kernel: str = "huber"
    keep_scans: bool = False
    relations: str | None = None
    scan_frame_offset: tuple[float, float, float] | None = None

    def __post_init__(self) -> None:
        if not (math.isfinite(self.resolution_m) and 1.0 / MAX_RESOLUTION <= self.resolution_m <= 1.0 / MIN_RESOLUTION):
            raise BagtoolsError(f"--resolution must be a cell side between {1.0 / MAX_RESOLUTION:g} and "
                                f"{1.0 / MIN_RESOLUTION:g} metres, got {self.resolution_m}")
        if self.max_range_m is not None and not (math.isfinite(self.max_range_m) and self.max_range_m > 0):
            raise BagtoolsError(f"--max-range must be a positive number of metres, got {self.max_range_m}")
        if not (math.isfinite(self.loop_search_radius_m) and self.loop_search_radius_m > 0):
            raise BagtoolsError(f"--loop-search-radius must be a positive number of metres, got {self.loop_search_radius_m}")
        if not (math.isfinite(self.loop_min_score) and 0.0 <= self.loop_min_score <= 1.0):
            raise BagtoolsError(f"--loop-min-score must be in [0, 1], got {self.loop_min_score}")
        if not (math.isfinite(self.loop_max_range_m) and self.loop_max_range_m > 0):
            raise BagtoolsError(f"loop_max_range_m must be a positive number of metres, got {self.loop_max_range_m}")
        if not self.topic:
            raise BagtoolsError("--topic must name a LaserScan topic")
        if self.scan_frame_offset is not None and (len(self.scan_frame_offset) != 3
                                                   or not all(math.isfinite(v) for v in self.scan_frame_offset)):
            raise BagtoolsError(f"--scan-frame-offset must be three numbers X,Y,YAW, got {self.scan_frame_offset!r}")

    @classmethod
    def from_params(cls, p: Mapping[str, Any]) -> SlamOptions:
        """The options ``bagtools slam`` was given: its click parameters by name (the command and its batch job
        build them here, so the two cannot differ)."""
        side, _ = map_cell_size(p["cell_size"], p["cells_per_metre"], p["resolution"], resolution_in_metres=True)
        return cls(topic=p["topic"], use_odometry=not p["no_odometry"], resolution_m=side, max_range_m=p["max_range"],
                   loop_search_radius_m=p["loop_search_radius"], loop_closure=not p["no_loop_closure"],
                   loop_min_score=p["loop_min_score"], keep_scans=not p["no_mcap"], relations=p["relations"],
                   scan_frame_offset=p["scan_frame_offset"])

    def back_end_options(self) -> BackEndOptions:
        """The back end's settings: the loop search with this run's radius, score and range."""
        if not self.loop_closure:
            return BackEndOptions(loop=None, loop_kernel=self.loop_kernel)
        max_range = self.loop_max_range_m if self.max_range_m is None else min(self.loop_max_range_m, self.max_range_m)
        loop = LoopOptions(search_radius_m=self.loop_search_radius_m, min_score=self.loop_min_score,
                           max_range_m=max_range)
        return BackEndOptions(loop=loop, loop_kernel=self.loop_kernel)


#: The front end: (bag path, options) -> its result, whose ``front_end`` holds every scan registered
#: (a :class:`~bagtools.odometry.steps.FrontEndRun`). The default is the laser odometry of bagtools.odometry.pipeline.
FrontEnd = Callable[[Path, SlamOptions], NdtOdomResult]


def front_end_options(options: SlamOptions) -> NdtOdomOptions:
    """The laser odometry's options for this run: its topic, odometry setting and laser mount."""
    return NdtOdomOptions(topic=options.topic, use_odometry=options.use_odometry,
                          scan_frame_offset=options.scan_frame_offset)


def laser_odometry(bag_path: Path, options: SlamOptions) -> NdtOdomResult:
    """The robust laser odometry of :mod:`bagtools.odometry.pipeline` with this run's topic and odometry setting
    (keeping the scans when results.mcap will replay them)."""
    return run_front_end(bag_path, front_end_options(options), keep_scans=options.keep_scans)


@dataclass
class SlamResult:
    """What a SLAM run produced (all poses of the robot base in the map frame, see the module docstring).

    ``trajectory``: optimized, every scan; ``odometry``: the front end alone;
    ``ground_truth``: /ground_truth in the map frame (None without it);
    ``grid``: the occupancy grid; ``back_end``: the graph and the loop
    candidates; ``loop_segments`` (L,2,2): the accepted loops' keyframe
    positions [[x_old, y_old], [x_new, y_new]] (m); ``summary``: summary.json;
    ``front_end``: the laser odometry's result (its scans when kept, the laser mount).
    """

    trajectory: Trajectory
    odometry: Trajectory
    ground_truth: Trajectory | None
    grid: OccupancyGrid
    back_end: BackEndResult
    loop_segments: np.ndarray
    summary: dict = field(default_factory=dict)
    front_end: NdtOdomResult | None = None


class SlamPipeline:
    """SLAM of one bag (see the module docstring).

    ``front_end`` replaces the laser odometry (e.g. a recorded run, in tests).
    """

    def __init__(self, bag_path: str | Path, options: SlamOptions | None = None,
                 front_end: FrontEnd | None = None) -> None:
        self.bag_path = Path(bag_path)
        self.options = options or SlamOptions()
        self.front_end = front_end or laser_odometry
        self.warnings: list[str] = []
        self.timing_s: dict[str, float] = {}

    def run(self) -> SlamResult:
        t0 = time.perf_counter()
        self._check_bag()
        relations = read_relations(self.options.relations) if self.options.relations else None  # before the work
        result = self._timed("front_end", self._front_end)
        front = result.front_end
        back = self._timed("back_end", lambda: self._back_end(front))
        trajectory, odometry = self._trajectories(front, back)
        base_frame = result.summary.get("base_frame") or None
        grid, map_summary = self._timed("map", lambda: self._map(trajectory, base_frame, result.clock))
        ground_truth = result.ground_truth
        evaluation = self._timed("evaluation", lambda: self._evaluate(ground_truth, relations, trajectory, odometry))
        self.timing_s["total"] = time.perf_counter() - t0
        loops = self._loop_segments(back)
        summary = self._summary(result, back, map_summary, evaluation)
        return SlamResult(trajectory, odometry, ground_truth, grid, back, loops, summary, result)

    def _timed(self, name: str, fn: Callable):
        t0 = time.perf_counter()
        out = fn()
        self.timing_s[name] = time.perf_counter() - t0
        return out

    # -- steps -------------------------------------------------------------------------------

    def _check_bag(self) -> None:
        """Refuse a bag without the scan topic, before any work."""
        with open_bag(self.bag_path) as bag:
            require_topic(bag, self.options.topic, LASERSCAN_TYPES, "LaserScan")
            if next(bag.messages([self.options.topic]), None) is None:
                raise BagtoolsError(f"topic {self.options.topic} holds no scans{bag.decode_note(self.options.topic)}",
                                    self.bag_path)

    def _front_end(self) -> NdtOdomResult:
        result = self.front_end(self.bag_path, self.options)
        self.warnings.extend(result.front_end.warnings or result.summary.get("warnings", []))
        if result.problem is not None or not result.front_end.steps:
            raise BagtoolsError(result.problem or f"no usable scan on {self.options.topic}", self.bag_path)
        return result

    def _back_end(self, front: FrontEndRun) -> BackEndResult:
        back = build_pose_graph(front.steps, self.options.back_end_options())
        self.warnings.extend(back.warnings)
        return back

    def _trajectories(self, front: FrontEndRun, back: BackEndResult) -> tuple[Trajectory, Trajectory]:
        """(optimized, front end) trajectories of every scan: keyframes at their nodes, others after their keyframe."""
        steps = front.steps
        node_of = {int(step): node for node, step in enumerate(back.keyframe_steps)}
        poses = np.empty((len(steps), 3))
        nodes = back.graph.poses
        for k, s in enumerate(steps):
            node = node_of.get(k)
            if node is not None:
                poses[k] = nodes[node]
            elif s.reference in node_of:
                poses[k] = se2_compose(nodes[node_of[s.reference]], s.T_ref_cur)
            else:  # matched against a scan that is no keyframe: follow the front end from the last keyframe
                last = node_of[max(i for i in node_of if i < k)]
                poses[k] = se2_compose(nodes[last], se2_between(steps[int(back.keyframe_steps[last])].pose, s.pose))
        poses[:, 2] = wrap_to_pi(poses[:, 2])
        stamps = front.stamps_ns()
        by_stamp = np.argsort(stamps, kind="stable")  # the steps are in recording order (see ndt-odom's _order)
        stamps = stamps[by_stamp]
        return (Trajectory(stamps, pose2tform(poses[by_stamp]).reshape(-1, 4, 4)),
                Trajectory(stamps, pose2tform(front.poses()[by_stamp]).reshape(-1, 4, 4)))

    def _map(self, trajectory: Trajectory, base_frame: str | None, clock: ScanClock) -> tuple[OccupancyGrid, dict]:
        """The grid of every scan at its optimized pose (``base_frame``: the robot frame the poses are of; ``clock``:
        how the front end timed the scans)."""
        o = self.options
        options = GridMapOptions(topic=o.topic, frame=SLAM_FRAME, poses="slam trajectory", resolution=1.0 / o.resolution_m,
                                 max_range_m=o.max_range_m or MAP_MAX_RANGE_M, base_frame=base_frame,
                                 scan_frame_offset=o.scan_frame_offset)
        result = GridMapPipeline(self.bag_path, options, trajectory=trajectory, clock=clock).run()
        # what the front end said already (perhaps with a hint after it) is not said again
        self.warnings.extend(w for w in result.summary.get("warnings", [])
                             if not any(said.startswith(w) for said in self.warnings))
        summary = {k: v for k, v in result.summary.items() if k not in ("options", "warnings", "bag", "poses")}
        return result.grid, summary

    def _evaluate(self, ground_truth: Trajectory | None, relations: Relations | None, trajectory: Trajectory,
                  odometry: Trajectory) -> dict:
        """The errors of SLAM and of the front end against the ground truth (in the map frame) and the relations,
        for those there are."""
        out: dict = {}
        if relations is not None:
            out["relations"] = {
                "file": str(self.options.relations),
                "metric": "Kuemmerle et al. 2009: per relation the translation (m) and rotation (deg) of "
                          "relation^-1 * (the trajectory's motion between its two stamps); mean, std, mean of squares",
                "slam": relation_errors(relations, trajectory),
                "front_end": relation_errors(relations, odometry),
            }
        if ground_truth is None:
            return out
        return {**out,
            "evaluation": {
                "reference": "ground_truth.tum (/ground_truth in the map frame, starting at the first scan's pose)",
                "ape_translation_m": "evo_ape tum ground_truth.tum <trajectory> (translation, no alignment)",
                "rpe_translation_m_per_1m": "evo_rpe tum ground_truth.tum <trajectory> --delta 1 --delta_unit m",
                "ape_aligned_m": "APE after the best planar rigid alignment (bagtools eval --align, evo_ape --align)",
                "relative_gap_N": "errors of the motion between scans N apart (bagtools eval --gap N)",
            },
            "errors_slam": trajectory_errors(ground_truth, trajectory),
            "errors_front_end": trajectory_errors(ground_truth, odometry),
        }

    def _loop_segments(self, back: BackEndResult) -> np.ndarray:
        pairs = [(c.old, c.new) for c in back.candidates if c.status == LoopOutcome.ACCEPTED]
        poses = back.graph.poses
        return np.array([[poses[a, :2], poses[b, :2]] for a, b in pairs]).reshape(-1, 2, 2)

    def _settings(self, cell_size_m: float | None) -> dict:
        """Every setting the run's front end and loop closure used, as run (the NDT cell the scans chose included):
        what a script needs to say how a trajectory was made."""
        back = self.options.back_end_options()
        front = asdict(front_end_options(self.options).front_end(cell_size_m)) if cell_size_m else None
        return {"front_end": front, "loop_closure": None if back.loop is None else asdict(back.loop),
                "back_end": {k: v for k, v in asdict(back).items() if k != "loop"}}

    def _summary(self, result: NdtOdomResult, back: BackEndResult, map_summary: dict, evaluation: dict) -> dict:
        front = result.front_end
        front_summary = {k: v for k, v in result.summary.items()
                         if k not in ("bag", "topic", "options", "warnings", "evaluation") and not k.startswith("errors_")}
        statuses = Counter(c.status for c in back.candidates)
        accepted = statuses.pop(LoopOutcome.ACCEPTED, 0)
        graph = back.graph
        opt = back.optimizations
        loops = [c for c in back.candidates if c.status == LoopOutcome.ACCEPTED]
        summary: dict = {
            "bag": str(self.bag_path),
            "topic": self.options.topic,
            "frame": "map: the front end's odometry frame at the first scan (the first keyframe held at its pose)",
            "scans": len(front.steps),
            "duration_s": float(np.ptp(front.stamps_ns()) / 1e9) if front.steps else 0.0,
            "keyframes": graph.n_nodes,
            "front_end": front_summary,
            "graph": {
                "nodes": graph.n_nodes,
                "odometry_edges": sum(c.kind == "odometry" for c in graph.constraints),
                "loop_edges": len(graph.loop_indexes()),
                **{k: v for k, v in back.counts.items() if v},
            },
            "loop_closure": {
                "enabled": self.options.loop_closure,
                "candidates": len(back.candidates),
                "accepted": accepted,
                "rejected": sum(statuses.values()),
                "rejected_by_reason": dict(statuses),
                "match_time_s": round(sum(c.time_s for c in back.candidates), 3),
                "accepted_loops": [c.as_dict() for c in loops],
            },
            "optimization": {
                "runs": len(opt),
                "iterations": sum(o.iterations for o in opt),
                "time_s": round(sum(o.time_s for o in opt), 4),
                "final_error": opt[-1].final_error if opt else 0.0,
                "final_error_before_last_run": opt[-1].initial_error if opt else 0.0,
                "solver": "GTSAM Levenberg-Marquardt; loops with a robust "
                          f"({self.options.loop_kernel}) noise model",
            },
            "map": map_summary,
            **evaluation,
            "timing_s": {k: round(v, 3) for k, v in self.timing_s.items()},
            "options": asdict(self.options),
            "settings": self._settings(front_summary.get("cell_size_m")),
            "warnings": list(dict.fromkeys(self.warnings)),
        }
        return summary
