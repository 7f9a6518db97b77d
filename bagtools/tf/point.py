"""``tf point``: follow points fixed in one frame through a bag, expressed in several target frames.

The classic experiment: a point fixed in ``map`` stays put in map, drifts in
``odom`` (as odometry drifts and localization corrects it) and sweeps around in
the robot's base frame as the robot drives.
"""

from __future__ import annotations

import csv
import io
import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from bagtools.errors import BagtoolsError
from bagtools.figures import tidy_layout
from bagtools.outputs import OutputDir, check_outputs
from bagtools.tf.buffer import TfBuffer
from bagtools.tf.track import format_stamp
from bagtools.tf.exceptions import ExtrapolationException
from bagtools.tf.sampling import sample_stamps

POINT_TYPES = ("geometry_msgs/msg/PointStamped",)
DEFAULT_TARGETS = ("map", "odom", "base_footprint")
"""Default target frames; a bag without base_footprint gets base_link as the robot's frame instead."""
OUTPUT_NAMES = ["point.csv", "point.png", "summary.json"]


MAX_POINT_COORDINATE_M = 1.0e5
"""A followed point farther than this from its frame's origin is refused (damage, or a typo)."""

@dataclass(frozen=True)
class FixedPoint:
    """A point ``xyz`` (metres) fixed in ``frame``; ``clicked_ns`` is the stamp it was clicked at, if any."""

    frame: str
    xyz: tuple[float, float, float]
    clicked_ns: int | None = None


@dataclass(frozen=True)
class PointTrack:
    """Every point at every time step in every target frame.

    ``stamp_ns`` (S,) int ns; ``xyz[target]`` (P, S, 3) metres, NaN where the
    transform is missing at a step (e.g. a gap in the data).
    """

    points: list[FixedPoint]
    targets: list[str]
    stamp_ns: np.ndarray
    xyz: dict[str, np.ndarray]


def follow_points(buffer: TfBuffer, points: list[FixedPoint], targets: list[str], rate_hz: float = 10.0) -> PointTrack:
    """Express each fixed point in each target frame at ``rate_hz`` over the span where all targets are available.

    Raises tf's exceptions for unknown or unconnected frames, and an
    ExtrapolationException when the targets have no common time span.
    """
    if not points:
        raise BagtoolsError("no points to follow", buffer.path)
    if not targets:
        raise BagtoolsError("no target frames to express the points in (give --targets A,B,...)", buffer.path)
    first, last = None, None
    for point in points:
        for target in targets:
            span = buffer.time_range(target, point.frame)
            if span is not None:
                first = span[0] if first is None else max(first, span[0])
                last = span[1] if last is None else min(last, span[1])
    if first is None:   # every path is static: one step is enough
        stamps = np.array([buffer.bag_span_ns[0] if buffer.bag_span_ns else 0], dtype=np.int64)
    elif first > last:
        raise ExtrapolationException(
            f"the frames {', '.join(targets)} have no common time span with {points[0].frame}: "
            f"data starts at {format_stamp(first)} but already ends at {format_stamp(last)}", buffer.path)
    else:
        stamps = sample_stamps(first, last, rate_hz)
    xyz: dict[str, np.ndarray] = {}
    for target in targets:
        out = np.full((len(points), stamps.size, 3), np.nan)
        for k, point in enumerate(points):
            T, valid = buffer.lookup(target, point.frame, stamps, return_mask=True)
            out[k] = T[:, :3, :3] @ np.asarray(point.xyz, dtype=np.float64) + T[:, :3, 3]
            out[k, ~valid] = np.nan
        xyz[target] = out
    return PointTrack(list(points), list(targets), stamps, xyz)


def point_csv(track: PointTrack) -> str:
    """One row per point and time step: point, stamp_ns, t_s (from the first step), then x, y, z per target."""
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(["point", "stamp_ns", "t_s"] + [f"{t}_{axis}_m" for t in track.targets for axis in "xyz"])
    t_s = (track.stamp_ns - track.stamp_ns[0]) / 1e9
    for k in range(len(track.points)):
        values = np.concatenate([track.xyz[t][k] for t in track.targets], axis=1)
        for stamp, seconds, row in zip(track.stamp_ns.tolist(), t_s.tolist(), values.tolist()):
            writer.writerow([k, stamp, f"{seconds:.6f}"] + ["" if np.isnan(v) else repr(v) for v in row])
    return out.getvalue()


def point_summary(track: PointTrack) -> dict:
    """Per point and target: first and last position, largest offset from the first, and path length (metres)."""
    per_point = []
    for k, point in enumerate(track.points):
        entry = {"frame": point.frame, "xyz": list(point.xyz), "clicked_ns": point.clicked_ns, "in_targets": {}}
        for target in track.targets:
            path = track.xyz[target][k]
            good = path[~np.isnan(path).any(axis=1)]
            if good.size == 0:
                entry["in_targets"][target] = None
                continue
            entry["in_targets"][target] = {
                "first_xyz_m": good[0].tolist(),
                "last_xyz_m": good[-1].tolist(),
                "max_offset_from_first_m": float(np.linalg.norm(good - good[0], axis=1).max()),
                "path_length_m": float(np.linalg.norm(np.diff(good, axis=0), axis=1).sum()),
            }
        per_point.append(entry)
    return {
        "targets": track.targets,
        "steps": int(track.stamp_ns.size),
        "first_stamp_ns": int(track.stamp_ns[0]),
        "last_stamp_ns": int(track.stamp_ns[-1]),
        "points": per_point,
    }


def plot_track(track: PointTrack, path: Path) -> None:
    """One column per target frame: the x-y path of every point (top) and its x, y over time (bottom), as PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = len(track.targets)
    fig, axes = plt.subplots(2, n, figsize=(4.5 * n, 7.5), squeeze=False, gridspec_kw={"height_ratios": [3, 2]})
    t_s = (track.stamp_ns - track.stamp_ns[0]) / 1e9
    for column, target in enumerate(track.targets):
        path_ax, time_ax = axes[0][column], axes[1][column]
        for k, point in enumerate(track.points):
            xyz = track.xyz[target][k]
            line, = path_ax.plot(xyz[:, 0], xyz[:, 1], lw=1.2, label=f"point {k} ({point.frame})")
            good = xyz[~np.isnan(xyz).any(axis=1)]
            if len(good):
                path_ax.plot(*good[0, :2], "o", color=line.get_color(), ms=5)
                path_ax.plot(*good[-1, :2], "s", color=line.get_color(), ms=5)
            time_ax.plot(t_s, xyz[:, 0], lw=1.0, color=line.get_color(), label=f"x, point {k}")
            time_ax.plot(t_s, xyz[:, 1], lw=1.0, ls="--", color=line.get_color(), label=f"y, point {k}")
        path_ax.set_title(f"in {target}  (o start, \u25a0 end)")
        path_ax.set_xlabel(f"x in {target} [m]")
        path_ax.set_ylabel(f"y in {target} [m]")
        path_ax.set_aspect("equal", adjustable="datalim")
        path_ax.grid(True, alpha=0.3)
        time_ax.set_xlabel("time since first step [s]")
        time_ax.set_ylabel(f"position in {target} [m]")
        time_ax.grid(True, alpha=0.3)
    axes[0][0].legend(fontsize=7, loc="best")
    axes[1][0].legend(fontsize=7, loc="best")
    tidy_layout(fig)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def read_clicked_points(bag: str | Path, topic: str) -> tuple[TfBuffer, list[FixedPoint]]:
    """One pass over the bag: its tf buffer and every geometry_msgs/PointStamped on ``topic``."""
    from bagtools.io import TfCollector, open_bag, stamp_to_ns

    collector = TfCollector()
    points: list[FixedPoint] = []
    not_finite = 0
    with open_bag(bag) as reader:
        collector.check(reader)
        reader.require_topic(topic, POINT_TYPES)
        wanted = [topic] + [t for t in collector.topics if t in reader.topics]
        for rec in reader.messages(wanted):
            if rec.topic == topic:
                p = rec.msg.point
                frame = rec.msg.header.frame_id.lstrip("/")
                if not all(math.isfinite(v) and abs(v) <= MAX_POINT_COORDINATE_M for v in (p.x, p.y, p.z)):
                    not_finite += 1
                    continue
                points.append(FixedPoint(frame, (float(p.x), float(p.y), float(p.z)), stamp_to_ns(rec.msg.header.stamp)))
            else:
                collector.add(rec)
        span, path, reader_warnings = (reader.start_ns, reader.end_ns), str(reader.path), list(reader.warnings)
    if not points:
        why = f" with a finite point ({not_finite} non-finite or beyond 1e5 m)" if not_finite else ""
        raise BagtoolsError(f"topic '{topic}' has no messages{why}", path)
    buffer = TfBuffer.from_arrays(*collector.arrays(), skip_invalid=True, repair_spikes=True)
    buffer.path, buffer.bag_span_ns = path, span
    if not_finite:
        reader_warnings.append(f"skipped {not_finite} point(s) on {topic} with a non-finite coordinate or one beyond 1e5 m")
    buffer.warnings[:0] = reader_warnings
    return buffer, points


def follow_point_bag(bag: str | Path, out_dir: str | Path, point: tuple[float, float, float] | None = None,
                     frame: str | None = None, topic: str | None = None, targets: list[str] | None = None,
                     rate_hz: float = 10.0, force: bool = False) -> tuple[PointTrack, list[str]]:
    """Follow ``point`` fixed in ``frame`` (or every clicked point of ``topic``) and write the outputs.

    Writes point.csv, point.png and summary.json into ``out_dir`` together.
    ``targets`` None means the frames of DEFAULT_TARGETS the bag has (base_link
    standing in for a missing base_footprint). Returns
    the track and warnings about skipped transforms.
    """
    if (point is None) == (topic is None) or (point is not None and not frame):
        raise BagtoolsError("give either --point X Y Z with --frame F, or --topic", bag)
    if point is not None and not all(math.isfinite(v) and abs(v) <= MAX_POINT_COORDINATE_M for v in point):
        raise BagtoolsError(f"--point must be three finite coordinates within 1e5 m, got {point}", bag)
    if not (math.isfinite(rate_hz) and rate_hz > 0):
        raise BagtoolsError(f"--rate must be a positive number of Hz, got {rate_hz}", bag)
    check_outputs(out_dir, OUTPUT_NAMES, force, inputs=[bag])  # before the work, not after it
    if topic is not None:
        buffer, points = read_clicked_points(bag, topic)
    else:
        buffer = TfBuffer.from_bag(bag)
        points = [FixedPoint(frame, tuple(float(v) for v in point))]
    if targets is None:
        targets = [t for t in DEFAULT_TARGETS if buffer.has_frame(t)]
        if "base_footprint" not in targets and buffer.has_frame("base_link"):
            targets.append("base_link")
        if not targets:
            raise BagtoolsError(f"none of the default target frames {', '.join(DEFAULT_TARGETS)} is in the bag; "
                                f"give --targets (frames: {', '.join(buffer.frames)})", buffer.path)
    track = follow_points(buffer, points, targets, rate_hz)
    summary = point_summary(track) | {"bag": str(bag), "rate_hz": rate_hz}
    with OutputDir(out_dir, OUTPUT_NAMES, force) as staged:
        (staged / "point.csv").write_text(point_csv(track))
        plot_track(track, staged / "point.png")
        (staged / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    return track, buffer.warnings
