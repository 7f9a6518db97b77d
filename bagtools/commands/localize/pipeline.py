"""``bagtools localize``: where the robot was in a map it already has, at every scan of a bag.

    LocalizePipeline(bag, options).run()
        _read()           the map; the scans, their order and odometry, as ndt-odom reads them
        _localize()       the laser odometry (ndt-odom's front end, with the wheels when used) as the motion,
                          every scan through MapLocalizer (bagtools.commands.localize.tracker): search, confirm, track;
                          then the tracked poses smoothed with the laser odometry and the revisits (a place seen
                          again, matched scans to scans) in one pose graph (bagtools.commands.localize.smoother), the map
                          matches weighed by their scores and held less their offset from the base (map_offset)
        _bag_localizer()  the bag's own map -> base (AMCL's map -> odom on /tf, or its /amcl_pose), where it has one
        _evaluate()       against /ground_truth (simulated bags): our error and the bag localizer's
        _summary()        per-scan scores and states, first fix, lost and recovered, the comparison

Frames: poses are the robot base's in the map frame (the nav2 map's); the
correction a localizer publishes is T_map_odom = T_map_base T_odom_base^-1.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field
from pathlib import Path

from typing import Any

import numpy as np

from bagtools.errors import BagtoolsError
from bagtools.grid import Nav2Map, read_nav2_map
from bagtools.io import BagReader, open_bag
from bagtools.commands.localize.smoother import map_offset, revisit_factors, smooth_track
from bagtools.commands.localize.hypotheses import Event
from bagtools.commands.localize.settings import CONFIRM_SCANS, TrackState
from bagtools.commands.localize.tracker import MapLocalizer
from bagtools.odometry.options import NdtOdomOptions
from bagtools.dataset import LaserDataset, ScanInputs
from bagtools.odometry.pipeline import laser_dataset, register_scans
from bagtools.odometry import FrontEndRun
from bagtools.progress import progress
from bagtools.scan_matching import CorrelativeReference
from bagtools.simtruth import read_ground_truth, read_poses
from bagtools.trajectory.evaluate import ape_aligned
from bagtools.trajectory import ErrorStats, Trajectory, ape_translation
from bagtools.transforms import pose2tform, se2_between, tform2pose, wrap_to_pi

MAP_FRAME = "map"
#: Where a bag with no map -> odom on /tf may record its localizer's pose (nav2's and ROS 1's AMCL).
AMCL_POSE_TOPIC = "/amcl_pose"
#: Where our poses and the bag's own localizer part by more than this (m, deg), the comparison says so.
PART_M, PART_DEG = 0.3, 10.0


@dataclass(frozen=True)
class LocalizeOptions:
    """What to localize and how: the scan ``topic``; ``initial_pose`` [x, y, yaw] of the base in the map
    (None: search the whole map); ``use_odometry`` (the wheels' motion as the prior of each scan);
    ``scan_frame_offset`` (x, y, yaw) of the laser on the base when tf lacks it; ``smooth`` (the tracked poses
    smoothed with the laser odometry, offline; False: each scan's own match, as an online localizer has it)."""

    topic: str = "/scan"
    initial_pose: tuple[float, float, float] | None = None
    use_odometry: bool = True
    scan_frame_offset: tuple[float, float, float] | None = None
    smooth: bool = True

    @classmethod
    def from_params(cls, p: Mapping[str, Any]) -> LocalizeOptions:
        """The options ``bagtools localize`` was given: its click parameters by name (the command and its batch job
        build them here, so the two cannot differ)."""
        return cls(topic=p["topic"], initial_pose=p["initial_pose"], use_odometry=not p["no_odometry"],
                   scan_frame_offset=p["scan_frame_offset"], smooth=not p["no_smoothing"])

    def __post_init__(self) -> None:
        for name, value in (("--initial-pose", self.initial_pose), ("--scan-frame-offset", self.scan_frame_offset)):
            if value is not None and (len(value) != 3 or not all(math.isfinite(float(v)) for v in value)):
                raise BagtoolsError(f"{name} must be three finite numbers X,Y,YAW, got {value!r}")


@dataclass
class LocalizeResult:
    """One bag localized in one map.

    ``stamps_ns`` (N,) of every usable scan (stamp order) with ``poses`` (N, 3) [x, y, theta] of the base in
    the map (NaN where unknown: before the first fix, while lost), ``scores`` (N,) and ``states`` (N,);
    ``trajectory`` the known poses as a Trajectory, ``map_to_odom`` the correction at them (None without
    odometry); ``bag_localizer`` the bag's own map -> base at the scan stamps (None when it has none);
    ``ground_truth`` the simulator's (None otherwise); ``events`` fixes, losses and recoveries.
    """

    nav2_map: Nav2Map
    stamps_ns: np.ndarray
    poses: np.ndarray
    scores: np.ndarray
    states: np.ndarray
    events: list[Event]
    trajectory: Trajectory
    map_to_odom: Trajectory | None
    bag_localizer: Trajectory | None
    ground_truth: Trajectory | None
    summary: dict
    base_frame: str = "base_link"
    scan_frame: str = ""
    T_base_scan: np.ndarray = field(default_factory=lambda: np.eye(4))
    scans: list = field(default_factory=list)
    odom_frame: str = "odom"
    odom_parent: str | None = None  # the odometry frame's parent in the bag's tf (a localizer's map), or None

    def map_to_odom_tf(self) -> tuple[str, Trajectory] | None:
        """(the bag's odometry frame, map -> odom at each localized scan) for results.mcap: the correction that hangs
        the bag's own tree under the map, when the run used odometry and the bag's odometry frame has no parent
        (else the result keeps its own tree); None otherwise."""
        if self.map_to_odom is None or self.odom_parent is not None or self.odom_frame in ("", MAP_FRAME):
            return None
        return self.odom_frame, self.map_to_odom


class LocalizePipeline:
    """Localizes one bag in one nav2 map (see the module docstring); ``keep_scans`` for results.mcap."""

    def __init__(self, bag_path: str | Path, map_yaml: str | Path, options: LocalizeOptions | None = None,
                 keep_scans: bool = False) -> None:
        self.bag_path = Path(bag_path)
        self.map_yaml = Path(map_yaml)
        self.options = options or LocalizeOptions()
        self.keep_scans = keep_scans
        self.warnings: list[str] = []
        self.revisits = 0  # revisit factors the smoother joined (bagtools.commands.localize.smoother.revisit_factors)
        self.timing_s: dict = {}  # seconds of each part of _localize (summary.json: timing_s)
        self.map_offset: np.ndarray | None = None  # the map matches' offset from the base (smoother.map_offset)
        self.bag_localizer_source = ""  # where the bag's own localization was read (summary.json: bag_localizer)

    def run(self) -> LocalizeResult:
        nav2_map = read_nav2_map(self.map_yaml)
        with open_bag(self.bag_path) as bag:
            dataset, inputs = self._read(bag)
            localizer, tracked, elapsed_s = self._localize(nav2_map, dataset, inputs)
            own = self._bag_localizer(bag, dataset, inputs)
            truth = self._ground_truth(bag, dataset)
        self.warnings = list(dict.fromkeys(dataset.warnings + self.warnings))
        stamps = inputs.stamps_ns
        poses = np.full((len(stamps), 3), np.nan)
        scores = np.zeros(len(stamps))
        states = np.empty(len(stamps), dtype=object)
        for step, k in enumerate(inputs.order):  # the localizer saw the scans in recording order
            states[k] = localizer.states[step]
            scores[k] = localizer.scores.get(step, 0.0)
            if step in tracked:
                poses[k] = tracked[step]
        events = [Event(e.kind, int(inputs.order[e.index]), e.stamp_ns, e.pose) for e in localizer.events]
        known = np.isfinite(poses).all(axis=1)
        self.fit = map_fit(localizer, self._front.run)
        if self.fit is not None and self.fit["ratio"] < MIN_MAP_FIT_RATIO:
            raise BagtoolsError(
                f"the scans do not fit the map {self.map_yaml}: where it placed them they score a median "
                f"{self.fit['map_score']:.2f} on it, against {self.fit['own_score']:.2f} on the bag's own neighbouring "
                f"scans (under {MIN_MAP_FIT_RATIO:g} of that): a map of another place, or at another scale (check its "
                "resolution)", self.bag_path)
        if not known.any():
            raise BagtoolsError(f"no scan on {self.options.topic} could be placed in the map {self.map_yaml}: none of "
                                f"the {len(stamps)} scans matched one place of it well enough (a bag from another "
                                "place, or a map that repeats itself everywhere the robot went?)", self.bag_path)
        trajectory = Trajectory(stamps[known], pose2tform(poses[known]))
        map_to_odom = None
        if inputs.odometry is not None:
            T_odom_base = inputs.odometry[0][known]
            map_to_odom = Trajectory(stamps[known], trajectory.poses @ np.linalg.inv(T_odom_base))
        result = LocalizeResult(nav2_map, stamps, poses, scores, states, events, trajectory, map_to_odom, own, truth,
                                {}, dataset.base_frame or dataset.scan_frame, dataset.scan_frame, inputs.T_base_scan,
                                dataset.scans, dataset.odom_frame, dataset.odometry_frame_parent())
        result.summary = self._summary(result, localizer, elapsed_s)
        if self.fit is not None:
            result.summary["map_fit"] = {k: (round(v, 4) if isinstance(v, float) else v) for k, v in self.fit.items()}
        return result

    # -- steps ------------------------------------------------------------------------------------

    def _front_end_options(self) -> NdtOdomOptions:
        """ndt-odom's options with this run's topic, odometry and laser mount: the laser odometry the localizer's
        motion prior is."""
        return NdtOdomOptions(topic=self.options.topic, use_odometry=self.options.use_odometry,
                              scan_frame_offset=self.options.scan_frame_offset)

    def _read(self, bag) -> tuple[LaserDataset, ScanInputs]:
        """The scans as ndt-odom reads them: usable scans, recording order, odometry at the stamps, mount."""
        dataset = laser_dataset(self._front_end_options(), keep_scans=self.keep_scans)
        inputs = dataset.read(bag)
        if len(inputs.stamps_ns) == 0:
            raise BagtoolsError(dataset.no_scan_problem(bag), self.bag_path)
        return dataset, inputs

    def _localize(self, nav2_map: Nav2Map, dataset: LaserDataset,
                  inputs: ScanInputs) -> tuple[MapLocalizer, dict[int, np.ndarray], float]:
        """Every scan, in recording order, through the localizer, its motion prior the laser odometry (ndt-odom's
        front end: the scans matched to each other, with the wheel odometry when the bag has it and used), then
        the tracked poses smoothed with that odometry and the revisits (unless not ``smooth``); returns the
        localizer, the poses (step in recording order -> [x, y, theta] in the map) and the seconds it all took."""
        points = nav2_map.occupied_points()
        try:
            localizer = MapLocalizer(points, nav2_map.resolution_m,
                                     None if self.options.initial_pose is None else np.array(self.options.initial_pose),
                                     sensor_xy=tuple(inputs.T_base_scan[:2, 3]), known=nav2_map.known,
                                     wall_faces=nav2_map.wall_faces())
        except ValueError as err:
            raise BagtoolsError(f"this map cannot be localized in: {err}", self.map_yaml) from err
        t0 = time.perf_counter()
        front, odom = register_scans(inputs, self._front_end_options())
        self._front = front
        self.warnings.extend(front.warnings(self.options.topic))
        t1 = time.perf_counter()
        by_state: dict[str, float] = {}
        for step, k in enumerate(progress(inputs.order, total=len(inputs.order), desc="localizing", unit="scan")):
            t = time.perf_counter()
            state = localizer.step(step, int(inputs.stamps_ns[k]), inputs.points_base(k), odom[k],
                                   continuous=front.run.steps[step].trusted)
            by_state[state] = by_state.get(state, 0.0) + time.perf_counter() - t
        t2 = time.perf_counter()
        poses = localizer.poses
        if self.options.smooth:
            cuts = [e.index for e in localizer.events if e.kind == "lost"]
            revisits = revisit_factors(front.run.steps, localizer.poses)
            self.revisits = len(revisits)
            self.map_offset = map_offset(front.run.steps, localizer.poses, localizer.matched, cuts)
            poses = smooth_track(front.run.steps, localizer.poses, localizer.matched, cuts=cuts, revisits=revisits,
                                 offset=self.map_offset, scores=localizer.scores)
        t3 = time.perf_counter()
        self.timing_s = {"laser_odometry": t1 - t0, "localizer": t2 - t1, "localizer_by_state": by_state,
                         "smoothing": t3 - t2, "total": t3 - t0}
        return localizer, poses, t3 - t0

    def _bag_localizer(self, bag: BagReader, dataset: LaserDataset, inputs: ScanInputs) -> Trajectory | None:
        """The bag's own map -> base at the scan stamps, or None: its localizer's map -> odom on /tf, composed with
        tf; else its /amcl_pose, carried between AMCL's updates by the odometry (AMCL holds its map -> odom from
        one update to the next: T_map_base(t) = T_map_base(k) T_odom_base(k)^-1 T_odom_base(t), k the last update
        at or before t)."""
        buffer, base = dataset.buffer, dataset.base_frame
        if (buffer is not None and base is not None and buffer.has_frame(MAP_FRAME)
                and buffer.can_transform(MAP_FRAME, base)):
            T, ok = buffer.lookup(MAP_FRAME, base, inputs.stamps_ns, return_mask=True)
            self.bag_localizer_source = f"/tf {MAP_FRAME} -> {base}"
            return Trajectory(inputs.stamps_ns[ok], T[ok]) if ok.any() else None
        amcl = read_poses(bag, AMCL_POSE_TOPIC, self.warnings)
        if amcl is None:
            return None
        stamps, T_map_base, frame, _ = amcl
        odom = dataset.odom_frame
        if buffer is None or base is None or not buffer.can_transform(odom, base):
            self.warnings.append(f"{AMCL_POSE_TOPIC} not compared: tf has no {odom} -> base to carry it between "
                                 "its updates")
            return None
        if frame.lstrip("/") != MAP_FRAME:
            self.warnings.append(f"{AMCL_POSE_TOPIC} is in frame '{frame}', not '{MAP_FRAME}': compared as if it were")
        T_odom_base, known = buffer.lookup(odom, base, stamps, return_mask=True)
        stamps, T_map_odom = stamps[known], T_map_base[known] @ np.linalg.inv(T_odom_base[known])
        k = np.searchsorted(stamps, inputs.stamps_ns, side="right") - 1
        after = np.flatnonzero(k >= 0)
        T_now, ok = buffer.lookup(odom, base, inputs.stamps_ns[after], return_mask=True)
        if not ok.any():
            return None
        self.bag_localizer_source = f"{AMCL_POSE_TOPIC}, held between updates by {odom} -> {base}"
        return Trajectory(inputs.stamps_ns[after[ok]], T_map_odom[k[after[ok]]] @ T_now[ok])

    def _ground_truth(self, bag, dataset: LaserDataset) -> Trajectory | None:
        """The simulator's /ground_truth of the base (map frame), or None."""
        truth = read_ground_truth(bag, warnings=self.warnings)
        if truth is None or dataset.buffer is None:
            return None
        stamps, T_map_gt, child = truth
        child, base = child.lstrip("/"), dataset.base_frame or dataset.scan_frame
        if child == base:
            return Trajectory(stamps, T_map_gt)
        if dataset.buffer.can_transform(child, base):
            return Trajectory(stamps, T_map_gt @ dataset.buffer.lookup(child, base, None))
        self.warnings.append(f"ground truth is of {child}, which tf does not connect to {base}: not evaluated")
        return None

    def _summary(self, result: LocalizeResult, localizer: MapLocalizer, elapsed_s: float) -> dict:
        stamps = result.stamps_ns
        duration_s = max((int(stamps[-1]) - int(stamps[0])) * 1e-9, 1e-9)
        fixes = [e for e in result.events if e.kind == "fix"]
        counts = {state: int(np.count_nonzero(result.states == state)) for state in TrackState}
        summary: dict = {
            "bag": str(self.bag_path),
            "map": str(self.map_yaml),
            "topic": self.options.topic,
            "base_frame": result.base_frame,
            "scans": len(stamps),
            "scans_localized": int(np.isfinite(result.poses).all(axis=1).sum()),
            "scans_by_state": counts,  # "lost" and "recovered" below count episodes
            "first_fix": None if not fixes else {
                "scan": fixes[0].index, "stamp_ns": fixes[0].stamp_ns,
                "seconds_after_first_scan": (fixes[0].stamp_ns - int(stamps[0])) * 1e-9},
            "lost": sum(e.kind == "lost" for e in result.events),
            "recovered": sum(e.kind == "recovered" for e in result.events),
            "corrected": sum(e.kind == "corrected" for e in result.events),
            "events": [{"kind": e.kind, "scan": e.index, "stamp_ns": e.stamp_ns,
                        "pose_xy_yaw": [float(e.pose[0]), float(e.pose[1]), float(wrap_to_pi(e.pose[2]))]}
                       for e in result.events],
            "global_searches": localizer.searches,
            "odometry_used": result.map_to_odom is not None,
            "smoothed": self.options.smooth,
            "revisits": self.revisits,
            "map_offset_m": None if self.map_offset is None else [float(v) for v in self.map_offset],
            "speed_x_real_time": duration_s / max(elapsed_s, 1e-9),
            "speed_x_real_time_tracking": _tracking_speed(duration_s, counts, self.timing_s),
            "timing_s": self.timing_s,
            "per_scan": {"stamp_ns": [int(s) for s in stamps], "state": [str(s) for s in result.states],
                         "score": [round(float(s), 4) for s in result.scores]},
            "options": asdict(self.options),
        }
        localized = result.scores[np.isfinite(result.poses).all(axis=1)]
        if localized.size:
            summary["score"] = ErrorStats.of(localized).as_dict()
        if counts[TrackState.AMBIGUOUS]:
            self.warnings.append(f"{counts[TrackState.AMBIGUOUS]} scan(s) matched several places of the map alike for "
                                 f"longer than the {CONFIRM_SCANS} scans a fix is confirmed over (a map that repeats "
                                 "itself)")
        if counts[TrackState.UNMAPPED]:
            self.warnings.append(f"{counts[TrackState.UNMAPPED]} scan(s) saw what the map does not have there (off the "
                                 "map, or a part it saw only from afar): their poses are carried by the laser odometry")
        if summary["lost"]:
            losses = [e for e in result.events if e.kind == "lost"]
            places = "; ".join(f"{e.stamp_ns * 1e-9:.2f} s at ({e.pose[0]:.2f}, {e.pose[1]:.2f})" for e in losses[:3])
            more = f" and {len(losses) - 3} more (summary.json: events)" if len(losses) > 3 else ""
            self.warnings.append(f"lost {summary['lost']} time(s), recovered {summary['recovered']}: {places}{more}")
        if result.bag_localizer is not None:
            summary["bag_localizer"] = self._compare(result.trajectory, result.bag_localizer)
        if result.ground_truth is not None:
            summary["ground_truth"] = {name: _errors(result.ground_truth, traj) for name, traj in
                                       (("ours", result.trajectory), ("bag_localizer", result.bag_localizer))
                                       if traj is not None and len(traj)}
        summary["warnings"] = self.warnings
        return summary

    def _compare(self, ours: Trajectory, theirs: Trajectory) -> dict:
        """Our poses against the bag's own localizer's over time, and where they part (see PART_M, PART_DEG)."""
        common, a, b = np.intersect1d(ours.stamps_ns, theirs.stamps_ns, return_indices=True)
        if common.size == 0:
            return {"source": self.bag_localizer_source, "scans_compared": 0}
        d = se2_between(tform2pose(theirs.poses[b]), tform2pose(ours.poses[a]))
        dist, heading = np.hypot(d[:, 0], d[:, 1]), np.degrees(np.abs(d[:, 2]))
        apart = (dist > PART_M) | (heading > PART_DEG)
        parts = []
        edges = np.flatnonzero(np.diff(np.r_[0, apart.astype(np.int8), 0]))
        for start, end in zip(edges[::2], edges[1::2]):
            parts.append({"from_ns": int(common[start]), "to_ns": int(common[end - 1]),
                          "max_translation_m": float(dist[start:end].max()),
                          "max_heading_deg": float(heading[start:end].max())})
        if parts:
            self.warnings.append(f"the bag's own localizer and ours part by more than {PART_M} m or {PART_DEG} deg "
                                 f"in {len(parts)} stretch(es), first at {parts[0]['from_ns'] * 1e-9:.2f} s")
        return {"source": self.bag_localizer_source, "scans_compared": int(common.size),
                "translation_m": ErrorStats.of(dist).as_dict(),
                "heading_deg": ErrorStats.of(heading).as_dict(), "threshold": {"m": PART_M, "deg": PART_DEG},
                "parts": parts, "difference": {"stamp_ns": [int(s) for s in common],
                                               "translation_m": [round(float(v), 4) for v in dist],
                                               "heading_deg": [round(float(v), 3) for v in heading]}}


#: The scans must fit the map at least this share as well as they fit their own neighbours (see :func:`map_fit`).
MIN_MAP_FIT_RATIO = 0.5
#: Scans sampled for the check, and how many neighbours on each side make each one's own map.
FIT_SAMPLE_SCANS, FIT_NEIGHBOURS = 50, 3


def map_fit(localizer: MapLocalizer, run: FrontEndRun) -> dict | None:
    """How well the scans fit the map, against how well they fit each other: for up to FIT_SAMPLE_SCANS of the
    scans the map placed by a match, the median of their scores on the map (the localizer's) and of their scores
    on the map of their FIT_NEIGHBOURS neighbours on each side (placed by the laser odometry, the same raster and
    kernel): what a right fix scores in this scene with this laser. None without matched scans."""
    matched = sorted(localizer.matched)
    if not matched:
        return None
    steps = run.steps
    sample = matched[:: max(1, len(matched) // FIT_SAMPLE_SCANS)]
    resolution = localizer.fine.resolution_m
    own, on_map = [], []
    for i in sample:
        near = [j for j in range(max(0, i - FIT_NEIGHBOURS), min(len(steps), i + FIT_NEIGHBOURS + 1)) if j != i]
        placed = []
        for j in near:
            T = se2_between(steps[i].pose, steps[j].pose)
            c, s = np.cos(T[2]), np.sin(T[2])
            placed.append(steps[j].points_base @ np.array([[c, s], [-s, c]]) + T[:2])
        points = np.vstack(placed) if placed else np.zeros((0, 2))
        if len(points) < 5 or len(steps[i].points_base) < 5:
            continue
        own.append(CorrelativeReference.from_points(points, resolution).score(steps[i].points_base, np.zeros(3)))
        on_map.append(localizer.scores[i])
    if not own:
        return None
    own_score, map_score = float(np.median(own)), float(np.median(on_map))
    return {"map_score": map_score, "own_score": own_score, "ratio": map_score / max(own_score, 1e-9),
            "scans": len(own)}


def _tracking_speed(duration_s: float, counts: dict[str, int], timing_s: dict) -> float | None:
    """Bag seconds per second while tracking (None: no scan tracked): the tracked scans' share of the bag's
    duration over the localizer's seconds on them plus their share of the laser odometry's and the smoothing's
    (shares by scan count). The time spent searching, or carrying the robot where the map explains nothing
    (unmapped), is left out: ``speed_x_real_time`` counts everything."""
    scans, tracked = sum(counts.values()), counts.get(TrackState.TRACKING, 0)
    if not tracked or not timing_s:
        return None
    share = tracked / scans
    spent = timing_s["localizer_by_state"].get(TrackState.TRACKING, 0.0) + share * (timing_s["laser_odometry"]
                                                                        + timing_s["smoothing"])
    return share * duration_s / max(spent, 1e-9)


def _errors(truth: Trajectory, estimate: Trajectory) -> dict:
    """APE of ``estimate`` against ``truth``: as it is (the map's frame is the truth's for a map of the same
    world), and after the best SE(2) alignment (a map made by SLAM has its own frame)."""
    out: dict = {}
    for name, fn in (("ape_m", ape_translation), ("ape_aligned_m", ape_aligned)):
        try:
            out[name] = fn(truth, estimate).as_dict()
        except BagtoolsError as err:
            out[name] = {"unavailable": err.problem}
    return out
