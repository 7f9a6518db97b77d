"""Occupancy-grid mapping with known poses: every laser scan of a bag into one 2-D grid.

    GridMapPipeline(bag, options).run()
        _load_tf()          the bag's tf buffer (small: /tf and /tf_static)
        _pose_source()      tf, /ground_truth or a TUM trajectory (see bagtools.dataset.poses)
        _map_scans()        per chunk of scans: batched pose lookup, grid growth; per scan: insert_ray
        _evaluate()         the map against the true world, for simulated bags

Each scan goes into the grid with MATLAB's insertRay semantics
(:meth:`bagtools.grid.OccupancyGrid.insert_ray`), from the scan frame's
position, each beam turned by the scan frame's orientation (a scanner mounted
upside down maps correctly). The beams follow the ROS LaserScan conventions
(REP 117): +inf means no return (free up to the maximum range), NaN and
values below range_min or finite values above range_max carry no information
and are ignored. The maximum range is the scan's range_max, lowered by
``--max-range``; returns at or beyond it mark free space only.

Nothing can be built, and the pipeline raises :class:`BagtoolsError`, when no
scan can be posed, or when no posed scan holds a single return within its range
limits (all NaN, infinite or out of range): such scans show no obstacle, so
there is no map. Scans with no valid range at all are skipped and counted;
scans with only +inf ranges still clear free space and are counted.

The grid starts at the bounds of the first chunk's scan positions plus the
maximum range and grows with each chunk; it is refused beyond
``options.max_cells`` (a bad pose must not allocate a huge grid).
"""

from __future__ import annotations

import math
import time
from collections import Counter
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from bagtools.dataset import (
    PosedScan, ScanClock, ScanPoseSource, ScanStream, TfScanPoses, TrajectoryScanPoses, posed_scan_chunks, scan_clock,
)
from bagtools.errors import BagtoolsError
from bagtools.grid import OccupancyGrid, rasterize_truth, score_map
from bagtools.grid.options import POSES_GROUND_TRUTH, POSES_TF, GridMapOptions
from bagtools.io import LASERSCAN_TYPES, BagReader, LaserScanArrays, open_bag, read_tf_arrays
from bagtools.io.decode import MAX_PLAUSIBLE_RANGE_M
from bagtools.limits import check_memory
from bagtools.simtruth import anchor_frame_in_map, load_sim_world, read_ground_truth
from bagtools.tf import TfBuffer, TransformException
from bagtools.tf.repair import guess_base_frame, repair_dynamic_tf

#: Memory a grid cell costs while a map is built and written (log-odds, the PGM, the PNG and its RGBA copies).
GRID_BYTES_PER_CELL = 40
from bagtools.trajectory import Trajectory, read_tum, read_tum_frames
from bagtools.transforms import pose2tform

SKIP_NO_VALID_RANGES = "no valid ranges"
SKIP_NO_MAX_RANGE = "range_max not positive (give --max-range)"
SCORE_TOLERANCE_CELLS = 1


@dataclass
class GridMapResult:
    """The grid (in ``options.frame``), the scan positions used ((N,2) metres, same frame) and the summary.

    With ``keep_scans`` the pipeline also keeps what results.mcap shows: ``scans``
    (every scan inserted, as decoded), ``T_frame_base`` (N,4,4) the robot base
    at each of their stamps, ``base_frame`` and ``T_base_scan`` (scan frame id ->
    (4,4), the laser mount used; the base stands for a scan frame tf lacks).
    """

    grid: OccupancyGrid
    scan_path_xy: np.ndarray
    summary: dict = field(default_factory=dict)
    scans: list[LaserScanArrays] = field(default_factory=list)
    T_frame_base: np.ndarray = field(default_factory=lambda: np.zeros((0, 4, 4)))
    base_frame: str | None = None
    T_base_scan: dict[str, np.ndarray] = field(default_factory=dict)


class GridMapPipeline:
    """Builds one occupancy grid from one bag (see the module docstring).

    ``trajectory``: poses of the robot base in ``options.frame`` computed by the
    caller (e.g. ``bagtools slam``'s optimized trajectory), used as a TUM file
    named by ``options.poses`` would be; ``options.poses`` then only labels them.
    ``keep_scans``: keep every inserted scan and its pose (for results.mcap).
    """

    def __init__(self, bag_path: str | Path, options: GridMapOptions, trajectory: Trajectory | None = None,
                 keep_scans: bool = False, clock: ScanClock | None = None) -> None:
        """``clock``: how the scans are timed (default: :func:`~bagtools.dataset.scan_clock` of the topic)."""
        self.bag_path = Path(bag_path)
        self.options = options
        self.trajectory = trajectory
        self.clock = clock
        self.keep_scans = keep_scans
        self._kept: list[LaserScanArrays] = []
        self._kept_T: list[np.ndarray] = []
        self.grid: OccupancyGrid | None = None
        self.skipped: Counter[str] = Counter()
        self.scans_total = 0
        self.scans_used = 0
        self.scans_without_returns = 0
        self.beams_used = 0
        self.returns_used = 0
        self.scan_frames: set[str] = set()
        self.max_ranges_m: set[float] = set()
        self.warnings: list[str] = []
        self._path: list[np.ndarray] = []
        self._scan_z: list[float] = []

    def run(self) -> GridMapResult:
        """Read the bag and build the grid; raises :class:`BagtoolsError` when nothing can be built."""
        t0 = time.perf_counter()
        with open_bag(self.bag_path) as bag:
            bag.require_topic(self.options.topic, LASERSCAN_TYPES)
            self._load_tf(bag)
            self.poses = self._pose_source(bag)
            grid = self._map_scans(bag)
            self.warnings = list(dict.fromkeys(list(bag.warnings) + self.buffer.warnings + self.poses.warnings
                                               + self.scan_stream.warnings() + self.warnings))
            if self.skipped[SKIP_NO_VALID_RANGES]:
                self.warnings.append(f"{self.skipped[SKIP_NO_VALID_RANGES]} scan(s) on {self.options.topic} skipped: "
                                     "no valid range")
            summary = self._summary(grid)
            summary["elapsed_s"] = round(time.perf_counter() - t0, 3)
            summary.update(self._evaluate(bag, grid))
            result = GridMapResult(grid, np.array(self._path).reshape(-1, 2), summary)
            if self.keep_scans:
                self._robot_poses(result)
        return result

    # -- steps -------------------------------------------------------------------

    def _load_tf(self, bag: BagReader) -> None:
        dynamic, static = read_tf_arrays(bag)
        poses_from_tf = self.options.poses_kind == POSES_TF and self.trajectory is None
        # what the repair drops is said only when tf places the scans (else it is not what the map was made from,
        # and a caller such as slam has said what its own reading of tf found)
        dynamic = repair_dynamic_tf(dynamic, self.warnings if poses_from_tf else [])[0]
        self.buffer = TfBuffer.from_arrays(dynamic, static, skip_invalid=True)
        if not poses_from_tf:
            return
        if not self.buffer.frames:
            raise BagtoolsError("bag has no /tf or /tf_static data, so scans cannot be placed in a frame "
                                "(try --poses ground-truth or --poses TRAJ.tum)", bag.path)
        if not self.buffer.has_frame(self.options.frame):
            known = ", ".join(self.buffer.frames)
            raise BagtoolsError(f"frame '{self.options.frame}' is not in the tf tree (frames: {known})", bag.path)

    def _base_frame(self, bag: BagReader) -> str | None:
        """The robot base frame: --base-frame, else /odom's child frame, else base_footprint/base_link in tf."""
        return guess_base_frame(bag, set(self.buffer.frames), self.options.base_frame)

    def _pose_source(self, bag: BagReader) -> ScanPoseSource:
        opts = self.options
        offset = None if opts.scan_frame_offset is None else pose2tform(np.asarray(opts.scan_frame_offset))
        if opts.poses_kind == POSES_TF and self.trajectory is None:
            self.base_frame = self._base_frame(bag)
            if offset is not None and not self.base_frame:
                raise BagtoolsError("--scan-frame-offset needs the robot base frame: give --base-frame", bag.path)
            return TfScanPoses(self.buffer, opts.frame, self.base_frame, offset)
        if opts.poses_kind == POSES_GROUND_TRUTH and self.trajectory is None:
            truth = read_ground_truth(bag, warnings=self.warnings)
            if truth is None:
                raise BagtoolsError("--poses ground-truth needs a /ground_truth topic (written by bagtools simulate)",
                                    bag.path)
            stamps, T_map_base, self.base_frame = truth
            return TrajectoryScanPoses(stamps, T_map_base, opts.frame, self.base_frame, self.buffer, offset)
        trajectory = self.trajectory if self.trajectory is not None else read_tum(opts.poses)
        named = None if self.trajectory is not None else read_tum_frames(opts.poses)  # as ndt-odom and slam write
        if named is not None and named[0] != opts.frame:
            raise BagtoolsError(f"the trajectory is in frame {named[0]!r}, not {opts.frame!r}: give --frame {named[0]}",
                                opts.poses)
        base = opts.base_frame or (named[1] if named else None) or self._base_frame(bag)
        if base is None:
            raise BagtoolsError("cannot tell which robot frame the trajectory describes: give --base-frame", opts.poses)
        self.base_frame = base
        return TrajectoryScanPoses(trajectory.stamps_ns, trajectory.poses, opts.frame, base, self.buffer, offset)

    def _map_scans(self, bag: BagReader) -> OccupancyGrid:
        # As ndt-odom and slam read them: a scan stamped at or before the one before it is placed by a wrong time.
        clock = self.clock or scan_clock(bag, self.options.topic)
        if not clock.usable and self.trajectory is None and self.options.poses_kind != "tum":
            raise BagtoolsError(f"the stamps of {self.options.topic} cannot time its scans ({clock.why}), so "
                                f"--poses {self.options.poses} cannot place them: map them with --poses TRAJ.tum from "
                                "`bagtools slam` or `ndt-odom`, which take them in logging order", bag.path)
        self.scan_stream = ScanStream(bag, self.options.topic, clock=clock, increasing=True, desc="grid")
        for chunk in posed_scan_chunks(self.scan_stream, self.poses):
            usable = [(item, ranges) for item in chunk if (ranges := self._usable_ranges(item)) is not None]
            if usable:
                grid = self._cover([item for item, _ in usable], bag.path)
            for item, ranges in usable:
                self._insert(grid, item, ranges)
        self.skipped.update(self.scan_stream.skipped)
        self.scans_total += sum(self.scan_stream.skipped.values())
        if self.grid is None or self.scans_used == 0:
            raise BagtoolsError(self._nothing_posed_message() + bag.decode_note(self.options.topic), bag.path)
        if self.returns_used == 0:
            raise BagtoolsError(
                f"no scan on {self.options.topic} has a return within its range limits (all NaN, infinite or out of "
                f"range in {self.scans_total} scans), so there is no obstacle to map", bag.path)
        # The grid grew to every scan's reach; keep what was seen and a 10-cell unknown border.
        return self.grid.cropped(margin_cells=10)

    def _usable_ranges(self, item: PosedScan) -> np.ndarray | None:
        """Count the scan; its ranges (see :meth:`_ranges`) if it can be inserted, else None (counted by reason)."""
        self.scans_total += 1
        self.scan_frames.add(item.scan.frame_id)
        if item.skip_reason:
            self.skipped[item.skip_reason] += 1
            return None
        if not math.isfinite(self._max_range(item)):
            self.skipped[SKIP_NO_MAX_RANGE] += 1
            return None
        ranges = self._ranges(item)
        if np.isnan(ranges).all():
            self.skipped[SKIP_NO_VALID_RANGES] += 1
            return None
        return ranges

    def _max_range(self, item: PosedScan) -> float:
        scan_max = item.scan.range_max_m
        limit = self.options.max_range_m
        if not (0 < scan_max < MAX_PLAUSIBLE_RANGE_M):  # no usable range_max in the message
            return limit if limit is not None else math.nan
        return scan_max if limit is None else min(scan_max, limit)

    def _ranges(self, item: PosedScan) -> np.ndarray:
        """Ranges (N,) float64 with the beams that carry no information set to NaN (see the module docstring)."""
        scan = item.scan
        r = scan.ranges_m.astype(np.float64)
        with np.errstate(invalid="ignore"):
            ignore = r < scan.range_min_m
            if math.isfinite(scan.range_max_m) and scan.range_max_m > 0:
                ignore |= np.isfinite(r) & (r > scan.range_max_m)
        r[ignore] = np.nan
        return r

    def _cover(self, chunk: list[PosedScan], bag_path: str | Path) -> OccupancyGrid:
        """Make the grid cover every scan position of ``chunk`` +- its maximum range, within the cell limit."""
        xy = np.array([item.T_frame_scan[:2, 3] for item in chunk])
        reach = np.array([self._max_range(item) for item in chunk])
        lo = (xy - reach[:, None]).min(axis=0)
        hi = (xy + reach[:, None]).max(axis=0)
        res = self.options.resolution
        if self.grid is not None:
            lo = np.minimum(lo, [self.grid.x_world_limits[0], self.grid.y_world_limits[0]])
            hi = np.maximum(hi, [self.grid.x_world_limits[1], self.grid.y_world_limits[1]])
        lo_cells, hi_cells = np.floor(lo * res), np.ceil(hi * res)
        cols, rows = (hi_cells - lo_cells).astype(float)
        check_memory(cols * rows * GRID_BYTES_PER_CELL, f"a grid of {cols:.0f} x {rows:.0f} cells at {res:g} cells/m",
                     "use coarser cells (--cell-size)")
        if cols * rows > self.options.max_cells:
            width, height = (hi - lo)
            raise BagtoolsError(
                f"the map would span {width:.0f} m x {height:.0f} m, {cols * rows:.3g} cells at {res:g} cells/m, "
                f"more than the limit of {self.options.max_cells:.3g}: check the poses (--poses, --frame) or use "
                "coarser cells (--cell-size)", bag_path)
        if self.grid is None:
            self.grid = OccupancyGrid(cols / res, rows / res, res, lo_cells / res)
        else:
            self.grid.grow_to_include(np.array([lo, hi]))
        return self.grid

    def _insert(self, grid: OccupancyGrid, item: PosedScan, ranges: np.ndarray) -> None:
        scan, T = item.scan, item.T_frame_scan
        max_range = self._max_range(item)
        keep = ~np.isnan(ranges)
        ranges, angles = ranges[keep], scan.angles_rad[keep]
        # each beam's direction in the map frame, projected on the map plane: exact for any
        # rotation of the scan frame about z, including a scanner mounted upside down
        cos_a, sin_a = np.cos(angles), np.sin(angles)
        world_angles = np.arctan2(T[1, 0] * cos_a + T[1, 1] * sin_a, T[0, 0] * cos_a + T[0, 1] * sin_a)
        grid.insert_ray(np.array([T[0, 3], T[1, 3], 0.0]), ranges, world_angles, max_range)
        returns = int(np.count_nonzero(ranges < max_range))
        self.scans_used += 1
        self.beams_used += int(ranges.size)
        self.returns_used += returns
        self.scans_without_returns += returns == 0
        self.max_ranges_m.add(round(max_range, 6))
        self._path.append(T[:2, 3].copy())
        self._scan_z.append(float(T[2, 3]))
        if self.keep_scans:
            self._kept.append(scan)
            self._kept_T.append(T)

    def _robot_poses(self, result: GridMapResult) -> None:
        """The kept scans, the base's pose at each and the laser mounts: T_frame_base = T_frame_scan @ inv(T_base_scan)."""
        base = getattr(self, "base_frame", None)
        mounts: dict[str, np.ndarray] = {}
        for scan in self._kept:
            if scan.frame_id not in mounts:
                mounts[scan.frame_id] = self._mount(base, scan.frame_id, scan.stamp_ns)
        T_frame_scan = np.array(self._kept_T).reshape(-1, 4, 4)
        inverse = {frame: np.linalg.inv(T) for frame, T in mounts.items()}
        T_scan_base = np.array([inverse[scan.frame_id] for scan in self._kept]).reshape(-1, 4, 4)
        result.scans, result.base_frame, result.T_base_scan = self._kept, base, mounts
        result.T_frame_base = T_frame_scan @ T_scan_base

    def _mount(self, base: str | None, scan_frame: str, stamp_ns: int) -> np.ndarray:
        """T_base_scan as the poses used it: --scan-frame-offset, else tf, else identity (the base stands for the scan)."""
        if self.options.scan_frame_offset is not None:
            return pose2tform(np.asarray(self.options.scan_frame_offset))
        if base and base != scan_frame and self.buffer.has_frame(base) and self.buffer.has_frame(scan_frame):
            for stamp in (stamp_ns, None):
                try:
                    return self.buffer.lookup(base, scan_frame, stamp)
                except TransformException:
                    continue
        return np.eye(4)

    def _nothing_posed_message(self) -> str:
        topic, frame = self.options.topic, self.options.frame
        if self.scans_total == 0:
            return f"topic {topic} holds no scans"
        reasons = ", ".join(f"{n} {why}" for why, n in self.skipped.most_common())
        scan_frames = ", ".join(sorted(self.scan_frames))
        known = ", ".join(self.buffer.frames) or "none"
        return (f"none of the {self.scans_total} scans on {topic} could be used in frame '{frame}' ({reasons}); "
                f"scan frame {scan_frames}, tf frames: {known}{self.buffer.invalid_note(*sorted(self.buffer.invalid_dropped))}")

    def _evaluate(self, bag: BagReader, grid: OccupancyGrid) -> dict:
        """For a simulated bag: the map against the true world rasterized at the map's cells.

        Scored over the cells in view, those the map observed (free or occupied):
        walls the robot never saw (behind obstacles, out of range) are not held
        against the map, a wall cell it crossed with free beams (drift, or a wall
        missed) is. Precision is over every occupied cell of the map against
        the whole truth. Occupied cells count within one cell (see
        :func:`bagtools.grid.score_map`). The counts of true cells in the whole
        grid are reported beside, to show how much of the world was in view.

        A map in another frame than map (odom, say) is first placed where that frame
        really was, anchored at the first ground-truth pose at which the pose source
        knows the robot (see :func:`bagtools.simtruth.anchor_frame_in_map`), so the
        score measures the drift within the map, not the frame's arbitrary origin.
        """
        world = load_sim_world(bag)
        if world is None:
            return {}
        result: dict = {}
        T_map_frame = np.eye(4)
        if self.options.frame != "map":
            truth = read_ground_truth(bag, warnings=self.warnings)
            if truth is None:
                return {}
            stamps, T_map_base, base = truth
            T_frame_base, reasons = self.poses.lookup(base, stamps)
            anchor = anchor_frame_in_map(T_map_base, T_frame_base, reasons == "")
            if anchor is None:
                return {}
            T_map_frame, first = anchor
            result["truth_anchor"] = {"frame": self.options.frame, "robot_frame": base, "stamp_ns": int(stamps[first])}
        R, t = T_map_frame[:2, :2], T_map_frame[:2, 3]
        scanner_z = float(np.median(self._scan_z)) + float(T_map_frame[2, 3])

        def in_map(xy: np.ndarray) -> np.ndarray:
            return xy @ R.T + t

        truly_occupied, truly_free = rasterize_truth(
            grid,
            lambda xy: world.surface_distance_2d_m(in_map(xy), z_m=scanner_z),
            lambda xy: world.clearance_m(in_map(xy)),
        )
        classes = grid.occupancy_matrix("ternary")
        in_view = classes != -1
        score = score_map(classes, truly_occupied & in_view, truly_free & in_view, tolerance_cells=SCORE_TOLERANCE_CELLS)
        # precision asks whether each occupied cell is near a true wall, seen or not
        whole = score_map(classes, truly_occupied, truly_free, tolerance_cells=SCORE_TOLERANCE_CELLS)
        result["accuracy_vs_truth"] = {
            **score.to_dict(),
            "occupied_precision": whole.to_dict()["occupied_precision"],
            "true_occupied_cells_in_grid": int(truly_occupied.sum()),
            "true_free_cells_in_grid": int(truly_free.sum()),
            "scanner_height_m": round(scanner_z, 4),
        }
        return result

    def _summary(self, grid: OccupancyGrid) -> dict:
        rows, cols = grid.grid_size
        x0, y0 = grid.grid_location_in_world
        classes = grid.occupancy_matrix("ternary")
        return {
            "bag": str(self.bag_path),
            "topic": self.options.topic,
            "frame": self.options.frame,
            "poses": self.options.poses,
            "base_frame": getattr(self, "base_frame", None),
            "scan_frames": sorted(self.scan_frames),
            "scans_total": self.scans_total,
            "scans_used": self.scans_used,
            "scans_skipped": dict(self.skipped),
            "scans_without_returns": self.scans_without_returns,
            "beams_used": self.beams_used,
            "returns_used": self.returns_used,
            "max_range_m": sorted(self.max_ranges_m),
            "grid": {
                "rows": rows, "cols": cols, "resolution_cells_per_m": grid.resolution,
                "cell_size_m": grid.cell_size_m, "origin_xy_m": [round(float(x0), 9) + 0.0, round(float(y0), 9) + 0.0],
                "occupied_cells": int(np.count_nonzero(classes == 1)),
                "free_cells": int(np.count_nonzero(classes == 0)),
            },
            "options": asdict(self.options),
            "warnings": self.warnings,
        }
