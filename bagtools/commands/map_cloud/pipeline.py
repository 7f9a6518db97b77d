"""Mapping with known poses: every cloud of a bag, moved into one fixed frame by tf.

The pipeline reads the bag once: the sensor topic and /tf, /tf_static together.
Each message is cut to range and sampled as it is read and held in its sensor
frame (:class:`~bagtools.commands.map_cloud.held.HeldClouds`: memory up to a budget, then
a temporary directory); once all of tf is read and repaired, the held clouds
are placed and accumulated, so memory is bounded by the map and the budget:

    CloudMapPipeline(bag, options).run()
        _read()             one pass: tf collected; per message: range cut, sampling, held
        _build_tf()         the tf buffer (and arrival times for --stamp latest)
        _place_clouds()     per held message: pose lookup, transform, accumulate
        _evaluate()         distance of the map to the true world, for simulated bags
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np

from bagtools.cloud.accumulator import MIN_VOXEL_M, MapCloud, PointAccumulator, random_indices
from bagtools.commands.map_cloud.held import HeldCloud, HeldClouds
from bagtools.commands.map_cloud.refine import CloudRefiner
from bagtools.dataset import SensorStream
from bagtools.dataset.scans import SensorPoints
from bagtools.io import LaserScanArrays
from bagtools.errors import BagtoolsError
from bagtools.io import LASERSCAN_TYPES, BagReader, TfCollector, open_bag
from bagtools.progress import progress
from bagtools.simtruth import anchor_frame_in_map, load_sim_world, read_ground_truth
from bagtools.tf.repair import NO_SCAN_TRANSFORM_WARNING, repair_dynamic_tf, guess_base_frame
from bagtools.tf import ConnectivityException, ExtrapolationException, LookupException, TfBuffer, TransformException
from bagtools.trajectory import Trajectory

StampMode = Literal["message", "latest"]

DEFAULT_CLOUD_SAMPLE = 0.01
"""Fraction of each PointCloud2 kept when no sample is given (a depth image holds thousands of points)."""
REFINE_CLOUD_SAMPLE = 0.1
"""The same with --refine: ICP registers each cloud on this share of its points."""


@dataclass(frozen=True)
class CloudMapOptions:
    """What to map and how.

    ``stamp``: 'message' looks each cloud's pose up at its header stamp
    (interpolated); 'latest' uses the newest transform that had arrived by the
    cloud's bag time, as a naive live subscriber would. ``sample`` keeps that
    random fraction of each cloud (seeded); None keeps DEFAULT_CLOUD_SAMPLE of
    a PointCloud2 and every beam of a LaserScan; ``voxel_m`` downsamples the map;
    ``max_range_m`` drops points farther than that from the sensor. ``refine``
    registers each cloud to the map built so far (Open3D's ICP,
    :mod:`bagtools.commands.map_cloud.refine`), starting where tf puts it; then
    ``sample`` defaults to REFINE_CLOUD_SAMPLE (ICP needs more of each cloud).
    """

    topic: str = "/camera/depth/points"
    frame: str = "map"
    stamp: StampMode = "message"
    sample: float | None = None
    voxel_m: float | None = None
    max_range_m: float | None = None
    seed: int = 0
    refine: bool = False

    @classmethod
    def from_params(cls, p: Mapping[str, Any]) -> CloudMapOptions:
        """The options ``bagtools map-cloud`` was given: its click parameters by name (the command and its batch
        job build them here, so the two cannot differ)."""
        return cls(topic=p["topic"], frame=p["frame"], stamp=p["stamp"], sample=p["sample"], voxel_m=p["voxel"],
                   max_range_m=p["max_range"], seed=p["seed"], refine=p["refine"])

    def __post_init__(self) -> None:
        if self.sample is not None and not 0.0 < self.sample <= 1.0:
            raise BagtoolsError(f"--sample must be in (0, 1], got {self.sample}")
        if self.voxel_m is not None and not (math.isfinite(self.voxel_m) and self.voxel_m >= MIN_VOXEL_M):
            raise BagtoolsError(f"--voxel must be a number of metres of at least {MIN_VOXEL_M:g}, got {self.voxel_m}")
        if self.max_range_m is not None and not (math.isfinite(self.max_range_m) and self.max_range_m > 0):
            raise BagtoolsError(f"--max-range must be a positive number of metres, got {self.max_range_m}")
        if self.seed < 0:
            raise BagtoolsError(f"--seed must be a non-negative integer, got {self.seed}")
        if self.stamp not in ("message", "latest"):
            raise BagtoolsError(f"--stamp must be 'message' or 'latest', got {self.stamp!r}")


@dataclass(frozen=True)
class PlacedInput:
    """One message that went into the map, as it went in (kept for results.mcap).

    ``points`` (N,3) float32 in the sensor frame ``frame_id`` after the range
    cut and sampling, with its ``intensity``/``rgb`` when the sensor gave them
    (``scan`` is the LaserScan itself for a scan topic); ``T_frame_sensor``
    (4,4) placed it in the map's frame at header ``stamp_ns``; ``base_frame``
    and ``T_base_sensor`` (4,4) are the robot base it hangs from in tf (None when
    tf does not connect them).
    """

    stamp_ns: int
    frame_id: str
    points: np.ndarray
    intensity: np.ndarray | None
    rgb: np.ndarray | None
    scan: LaserScanArrays | None
    T_frame_sensor: np.ndarray
    base_frame: str | None
    T_base_sensor: np.ndarray | None


@dataclass
class CloudMapResult:
    """The map in ``options.frame`` (points (N,3) float32, intensity and colour when the sensor gave them),
    the sensor positions used, the summary, and (when asked for) every message as it went into the map."""

    cloud: MapCloud
    sensor_path: np.ndarray
    summary: dict = field(default_factory=dict)
    inputs: list[PlacedInput] = field(default_factory=list)
    #: with --refine: the refined poses of the robot base (or of the sensor, when tf ties it to no base) in the
    #: map's frame, one per placed cloud in bag order, and the body frame they are of
    trajectory: Trajectory | None = None
    trajectory_body: str | None = None

    @property
    def points(self) -> np.ndarray:
        """The map's points (N,3) float32."""
        return self.cloud.points


def _skip_reason(err: TransformException) -> str:
    """A short reason for the skip counts in summary.json."""
    if isinstance(err, ExtrapolationException):
        return "outside tf data"
    if isinstance(err, LookupException):
        return "unknown frame"
    if isinstance(err, ConnectivityException):
        return "frames not connected"
    return "invalid transform"


class CloudMapPipeline:
    """Builds one point-cloud map from one bag (see the module docstring)."""

    def __init__(self, bag_path: str | Path, options: CloudMapOptions, keep_inputs: bool = False) -> None:
        """``keep_inputs``: keep every placed message's points (:attr:`CloudMapResult.inputs`, for results.mcap)."""
        self.bag_path = Path(bag_path)
        self.options = options
        self.keep_inputs = keep_inputs
        self.inputs: list[PlacedInput] = []
        self._base_of: dict[str, np.ndarray | None] = {}
        self.rng = np.random.default_rng(options.seed)
        self.accumulator = PointAccumulator(options.voxel_m)
        self.skipped: Counter[str] = Counter()
        self.clouds_used = 0
        self.points_in = 0
        self.sensor_frames: set[str] = set()
        self._sensor_path: list[np.ndarray] = []
        self._refined: list[tuple[int, np.ndarray, str]] = []  # with --refine: (stamp, T_frame_body, body)
        self.refiner: CloudRefiner | None = None

    def run(self) -> CloudMapResult:
        with open_bag(self.bag_path) as bag:
            bag.require_topic(self.options.topic)
            self.warnings = list(bag.warnings)
            held = HeldClouds()
            try:
                collector = self._read(bag, held)
                self._build_tf(bag, collector)
                self._place_clouds(held)
            finally:
                held.close()
            empty = [f"{self.skipped['empty cloud']} message(s) on {self.options.topic} skipped: no valid point"] \
                if self.skipped["empty cloud"] else []
            self.warnings = list(dict.fromkeys(list(bag.warnings) + self.warnings + self.stream.warnings() + empty))
            if self.clouds_used == 0:
                reasons = ", ".join(f"{n} {why}" for why, n in self.skipped.items()) or "no messages"
                invalid = self.buffer.invalid_note(*sorted(self.buffer.invalid_dropped))
                raise BagtoolsError(f"no cloud on {self.options.topic} could be placed in frame '{self.options.frame}' "
                                    f"({reasons}), so there is no map to write{invalid}"
                                    f"{bag.decode_note(self.options.topic)}", bag.path)
            cloud = self.accumulator.cloud()
            points = cloud.points
            if points.shape[0] == 0:
                limit = f" within --max-range {self.options.max_range_m} m" if self.options.max_range_m is not None else ""
                raise BagtoolsError(f"none of the {self.clouds_used} placed clouds on {self.options.topic} has a point"
                                    f"{limit}, so there is no map to write", bag.path)
            summary = self._summary(cloud)
            summary.update(self._evaluate(bag, points))
        trajectory, body = self._refined_trajectory()
        return CloudMapResult(cloud, np.array(self._sensor_path).reshape(-1, 3), summary, self.inputs, trajectory, body)

    # -- steps -------------------------------------------------------------------

    def _read(self, bag: BagReader, held: HeldClouds) -> TfCollector:
        """One pass over the sensor topic and tf: each message cut, sampled and held; tf collected."""
        opts = self.options
        if opts.refine and bag.topics[opts.topic].msgtype in LASERSCAN_TYPES:
            raise BagtoolsError(f"--refine registers 3D clouds; {opts.topic} holds laser scans, which lie in one plane "
                                f"(ICP to planes cannot move them in it): `bagtools slam` matches scans", bag.path)
        self.sample = opts.sample if opts.sample is not None else (
            1.0 if bag.topics[opts.topic].msgtype in LASERSCAN_TYPES
            else REFINE_CLOUD_SAMPLE if opts.refine else DEFAULT_CLOUD_SAMPLE)
        collector = TfCollector()
        collector.check(bag)
        self.stream = SensorStream(bag, opts.topic, desc=None, attributes=True)
        tf_topics = [t for t in collector.topics if t in bag.topics and t != opts.topic]
        records = bag.messages([opts.topic, *tf_topics], from_cdr={**collector.from_cdr, **self.stream.from_cdr})
        total = sum(bag.topics[t].count for t in (opts.topic, *tf_topics))
        for rec in progress(records, total=total, desc="reading", unit="msg"):
            if rec.topic != opts.topic:
                collector.add(rec)
            elif (item := self.stream.decode(rec)) is not None:
                self._hold(item, held)
        self.skipped.update(self.stream.skip_counts)
        return collector

    def _hold(self, item: SensorPoints, held: HeldClouds) -> None:
        """Range cut and sampling of one message, kept in its sensor frame until tf is known."""
        self.sensor_frames.add(item.frame_id)
        self.points_in += item.points.shape[0]
        if item.points.shape[0] == 0:
            self.skipped["empty cloud"] += 1
            return
        sensed = MapCloud(item.points, item.intensity, item.rgb)
        if self.options.max_range_m is not None:
            points = item.points
            sensed = sensed.select(np.einsum("ij,ij->i", points, points) <= self.options.max_range_m**2)
        index = random_indices(len(sensed), self.sample, self.rng)
        if index is not None:
            sensed = sensed.select(index)
        held.add(HeldCloud(item.stamp_ns, item.log_time_ns, item.frame_id, sensed,
                           item.scan if self.keep_inputs else None))

    def _build_tf(self, bag: BagReader, collector: TfCollector) -> None:
        dynamic, static = collector.arrays()
        arrival_ns = collector.dynamic_arrival_ns()
        dynamic, kept = repair_dynamic_tf(dynamic, self.warnings)
        arrival_ns = arrival_ns[kept]
        self.buffer = TfBuffer.from_arrays(dynamic, static, skip_invalid=True)
        self.warnings.extend(self.buffer.warnings)
        self._arrival = _ArrivalIndex(dynamic, arrival_ns)
        self.base_frame = guess_base_frame(bag, set(self.buffer.frames))
        if not self.buffer.frames:
            raise BagtoolsError("bag has no /tf or /tf_static data, so clouds cannot be placed in a frame", bag.path)
        if not self.buffer.has_frame(self.options.frame):
            known = ", ".join(self.buffer.frames)
            raise BagtoolsError(f"frame '{self.options.frame}' is not in the tf tree (frames: {known})", bag.path)

    def _pose(self, sensor_frame: str, stamp_ns: int, log_time_ns: int) -> tuple[np.ndarray, str, int]:
        """(T_frame_sensor, the tf frame used for the sensor, the stamp looked up at) for one message, by the
        chosen stamp policy (raises TransformException).

        A sensor frame the bag's tf lacks is taken to be the robot base frame, with a warning.
        """
        target = self.options.frame
        sensor_frame = sensor_frame.lstrip("/")
        if not self.buffer.has_frame(sensor_frame) and self.base_frame and self.buffer.has_frame(self.base_frame):
            warning = NO_SCAN_TRANSFORM_WARNING.format(base=self.base_frame, scan_frame=sensor_frame)
            if warning not in self.warnings:
                self.warnings.append(warning)
            sensor_frame = self.base_frame
        if self.options.stamp == "latest":
            chain = self.buffer.chain_edges(target, sensor_frame)
            stamp_ns = self._arrival.latest_common_stamp(chain, log_time_ns)
        return self.buffer.lookup(target, sensor_frame, stamp_ns), sensor_frame, stamp_ns

    def _base_sensor(self, tf_frame: str, stamp_ns: int) -> np.ndarray | None:
        """T_base_sensor of a sensor's tf frame (looked up once per frame), None when tf does not connect them."""
        if tf_frame not in self._base_of:
            T = None
            if self.base_frame and self.buffer.has_frame(self.base_frame):
                try:
                    T = self.buffer.lookup(self.base_frame, tf_frame, stamp_ns)
                except TransformException:
                    T = None
            self._base_of[tf_frame] = T
        return self._base_of[tf_frame]

    def _place_clouds(self, held: HeldClouds) -> None:
        """Each held message placed by tf (and registered to the map so far, with --refine), transformed into the
        map's frame and accumulated."""
        refiner = self.refiner = CloudRefiner() if self.options.refine else None
        for item in progress(held, total=held.count, desc="refining" if refiner else "mapping", unit="msg"):
            try:
                T_frame_sensor, tf_frame, stamp_used = self._pose(item.frame_id, item.stamp_ns, item.log_time_ns)
            except TransformException as err:
                self.skipped[_skip_reason(err)] += 1
                continue
            sensed = item.cloud
            if refiner is not None:
                T_frame_sensor = refiner.refine(sensed.points, T_frame_sensor, sensed.rgb)
                T_base_sensor = self._base_sensor(tf_frame, stamp_used)
                body = self.base_frame if T_base_sensor is not None else tf_frame
                T_frame_body = T_frame_sensor if T_base_sensor is None else T_frame_sensor @ np.linalg.inv(T_base_sensor)
                self._refined.append((item.stamp_ns, T_frame_body, body))
            R, t = T_frame_sensor[:3, :3], T_frame_sensor[:3, 3]
            self.accumulator.add((sensed.points.astype(np.float64) @ R.T + t).astype(np.float32), sensed.intensity,
                                 sensed.rgb)
            self._sensor_path.append(t.copy())
            self.clouds_used += 1
            if self.keep_inputs:
                T_base_sensor = self._base_sensor(tf_frame, stamp_used)
                self.inputs.append(PlacedInput(item.stamp_ns, item.frame_id, sensed.points, sensed.intensity, sensed.rgb,
                                               item.scan, T_frame_sensor,
                                               self.base_frame if T_base_sensor is not None else None, T_base_sensor))

    def _refined_trajectory(self) -> tuple[Trajectory | None, str | None]:
        """The refined poses as a trajectory in stamp order (one pose per stamp), and its body frame."""
        if not self._refined:
            return None, None
        stamps = np.array([stamp for stamp, _, _ in self._refined], dtype=np.int64)
        order = np.argsort(stamps, kind="stable")
        keep = order[np.r_[True, np.diff(stamps[order]) > 0]]
        poses = np.stack([self._refined[k][1] for k in keep])
        return Trajectory(stamps[keep], poses), self._refined[0][2]

    def _evaluate(self, bag: BagReader, points: np.ndarray) -> dict:
        """For a simulated bag: distances of the map's points to the true world surfaces.

        A map in another frame than map (odom, say) is first placed in the world
        where that frame really was: anchored at the first ground-truth pose at
        which the frame -> robot transform is known, so what remains is the
        drift of the frame, not its arbitrary origin.
        """
        world = load_sim_world(bag)
        if world is None:
            return {}
        T_map_frame = np.eye(4)
        result: dict = {}
        if self.options.frame != "map":
            truth = read_ground_truth(bag, warnings=self.warnings)
            if truth is None:
                return {}
            stamps, T_map_base, base = truth
            T_frame_base, valid = self.buffer.lookup(self.options.frame, base, stamps, return_mask=True)
            anchor = anchor_frame_in_map(T_map_base, T_frame_base, valid)
            if anchor is None:
                return {}
            T_map_frame, first = anchor
            result["truth_anchor"] = {"frame": self.options.frame, "robot_frame": base, "stamp_ns": int(stamps[first])}
        in_map = points.astype(np.float64) @ T_map_frame[:3, :3].T + T_map_frame[:3, 3]
        result["accuracy_vs_truth_m"] = _distance_stats(world.surface_distance_m(in_map))
        return result

    def _summary(self, cloud: MapCloud) -> dict:
        if self.accumulator.dropped:
            self.warnings.append(f"{' and '.join(sorted(self.accumulator.dropped))} left out of the map: some messages on "
                                 f"{self.options.topic} have it and some do not")
        return {
            "bag": str(self.bag_path),
            "topic": self.options.topic,
            "frame": self.options.frame,
            "sensor_frames": sorted(self.sensor_frames),
            "clouds_used": self.clouds_used,
            "clouds_skipped": dict(self.skipped),
            "points_in": self.points_in,
            "points_accumulated": self.accumulator.points_added,
            "points_out": len(cloud),
            "fields": cloud.fields,
            "sample_fraction": self.sample,
            **({} if self.refiner is None else {"refined": {
                "clouds_registered": self.refiner.registered,
                "clouds_kept_at_tf_pose": self.clouds_used - self.refiner.registered,
                "median_fitness": float(np.median(self.refiner.fitness)) if self.refiner.fitness else None}}),
            "options": asdict(self.options),
            "warnings": self.warnings,
        }


def _distance_stats(distances_m: np.ndarray) -> dict:
    if distances_m.size == 0:
        return {"points": 0}
    return {
        "points": int(distances_m.size),
        "mean": float(distances_m.mean()),
        "median": float(np.median(distances_m)),
        "p95": float(np.percentile(distances_m, 95)),
    }


class _ArrivalIndex:
    """For each tf edge, the newest header stamp that had arrived by a given bag time."""

    def __init__(self, dynamic, arrival_ns: np.ndarray) -> None:
        self._by_edge: dict[tuple[str, str], tuple[np.ndarray, np.ndarray]] = {}
        parents = np.array([p.lstrip("/") for p in dynamic.parent], dtype=object)
        children = np.array([c.lstrip("/") for c in dynamic.child], dtype=object)
        for parent, child in set(zip(parents, children)):
            rows = np.flatnonzero((parents == parent) & (children == child))
            order = np.argsort(arrival_ns[rows], kind="stable")
            arrivals = arrival_ns[rows][order]
            newest = np.maximum.accumulate(dynamic.stamp_ns[rows][order])
            self._by_edge[(parent, child)] = (arrivals, newest)

    def latest_common_stamp(self, chain: list[tuple[str, str]], log_time_ns: int) -> int:
        """min over the chain's dynamic edges of the newest stamp arrived by ``log_time_ns``.

        Static edges do not count (as in tf2). Raises ExtrapolationException when
        an edge had no data yet.
        """
        stamps = []
        for edge in chain:
            entry = self._by_edge.get(edge)
            if entry is None:
                continue
            arrivals, newest = entry
            i = int(np.searchsorted(arrivals, log_time_ns, side="right")) - 1
            if i < 0:
                raise ExtrapolationException(f"no transform {edge[0]} -> {edge[1]} had arrived by bag time {log_time_ns}")
            stamps.append(int(newest[i]))
        return min(stamps) if stamps else 0
