"""``tf echo`` over a bag: one transform sampled at a fixed rate, like tf2_echo."""

from __future__ import annotations

import csv
import difflib
import io
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from bagtools.tf.buffer import TfBuffer
from bagtools.tf.track import format_stamp
from bagtools.tf.exceptions import ExtrapolationException, LookupException
from bagtools.tf.sampling import sample_stamps
from bagtools.transforms import quat2eul, xyzw2quat


@dataclass(frozen=True)
class EchoTable:
    """The pose of ``source`` in ``target`` at ``stamp_ns`` (N,) int ns.

    ``translation`` (N,3) metres; ``rotation_xyzw`` (N,4) ROS order, w >= 0;
    ``rpy`` (N,3) roll, pitch, yaw in radians (intrinsic ZYX, as tf2_echo).
    """

    target: str
    source: str
    stamp_ns: np.ndarray
    translation: np.ndarray
    rotation_xyzw: np.ndarray
    rpy: np.ndarray


def echo_transform(buffer: TfBuffer, target: str, source: str, rate_hz: float = 1.0) -> EchoTable:
    """Sample T_target_source at ``rate_hz`` over the span where the transform exists.

    An all-static path gives one row (at the bag start if known, else 0).
    Stamps inside the span that still have no transform (a parent change, a
    gap) are left out. Raises tf's exceptions for unknown frames, unconnected
    trees, or transforms that never overlap in time.
    """
    span = buffer.time_range(target, source)
    if span is None:
        stamps = np.array([buffer.bag_span_ns[0] if buffer.bag_span_ns else 0], dtype=np.int64)
    else:
        first, last = span
        if first > last:
            raise ExtrapolationException(
                f"the transforms between [{source}] and [{target}] never overlap in time: the latest data of one "
                f"ends at {format_stamp(last)} before another starts at {format_stamp(first)}", buffer.path)
        stamps = sample_stamps(first, last, rate_hz)
    translation, rotation, valid = buffer.lookup_pose(target, source, stamps, return_mask=True)
    stamps, translation, rotation = stamps[valid], translation[valid], rotation[valid]
    ypr = quat2eul(xyzw2quat(rotation), "ZYX") if len(rotation) else np.empty((0, 3))
    return EchoTable(target, source, stamps, translation, rotation, np.asarray(ypr).reshape(-1, 3)[:, ::-1])


def format_echo(table: EchoTable) -> str:
    """tf2_echo's text: per stamp the translation, quaternion and RPY in radians and degrees."""
    blocks = []
    for k in range(table.stamp_ns.size):
        t, q, rpy = table.translation[k], table.rotation_xyzw[k], table.rpy[k]
        blocks.append(
            f"At time {format_stamp(int(table.stamp_ns[k]))}\n"
            f"- Translation: [{t[0]:.3f}, {t[1]:.3f}, {t[2]:.3f}]\n"
            f"- Rotation: in Quaternion (xyzw) [{q[0]:.3f}, {q[1]:.3f}, {q[2]:.3f}, {q[3]:.3f}]\n"
            f"- Rotation: in RPY (radian) [{rpy[0]:.3f}, {rpy[1]:.3f}, {rpy[2]:.3f}]\n"
            f"- Rotation: in RPY (degree) [{np.degrees(rpy[0]):.3f}, {np.degrees(rpy[1]):.3f}, {np.degrees(rpy[2]):.3f}]"
        )
    return "\n".join(blocks)


ECHO_COLUMNS = ["stamp_ns", "x_m", "y_m", "z_m", "qx", "qy", "qz", "qw", "roll_rad", "pitch_rad", "yaw_rad"]


def echo_csv(table: EchoTable) -> str:
    """The table as CSV text with a header row (stamps as int ns, values full precision)."""
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(ECHO_COLUMNS)
    values = np.hstack([table.translation, table.rotation_xyzw, table.rpy])
    for stamp, row in zip(table.stamp_ns.tolist(), values.tolist()):
        writer.writerow([stamp, *(repr(v) for v in row)])
    return out.getvalue()


def echo_bag(bag: str | Path, target: str, source: str, rate_hz: float = 1.0) -> tuple[EchoTable, list[str]]:
    """Load the bag's tf and sample the transform: (table, warnings about skipped transforms)."""
    buffer = TfBuffer.from_bag(bag)
    for frame in (target, source):
        if frame and not frame.startswith("/") and frame not in buffer.frames:
            raise LookupException(f"frame '{frame}' is not in the bag's tf ({nearest_frames(frame, buffer.frames)})",
                                  Path(bag))
    return echo_transform(buffer, target, source, rate_hz), buffer.warnings


def nearest_frames(frame: str, frames: list[str], n: int = 3) -> str:
    """The bag's frames nearest to ``frame`` by name, as a phrase ("nearest by name: a, b, c")."""
    if not frames:
        return "it has no frames"
    nearest = difflib.get_close_matches(frame, frames, n=n, cutoff=0.0)
    return f"nearest by name: {', '.join(nearest)}; {len(frames)} frame(s) in all, see `bagtools tf frames`"
