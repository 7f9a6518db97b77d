"""Repairs for the tf data of real recordings, shared by every command that replays a bag.

- Corrupt samples: a real TurtleBot3 bag holds odometry at 1e22..1e32 m for a few
  samples (a serial link corrupting messages); one such sample would ruin every
  pose after it. :func:`drop_translation_spikes` removes such isolated leaps.
- A missing laser mount: some bags have no base -> scan transform; commands then
  take the scan frame to be the base frame and say so with
  :data:`NO_SCAN_TRANSFORM_WARNING`.
"""

from __future__ import annotations

from collections import Counter

import numpy as np
from scipy.ndimage import median_filter

from bagtools.io import ODOMETRY_TYPES, BagReader, TfArrays, decode_odometry

BASE_FRAME_CANDIDATES = ("base_footprint", "base_link")
"""Conventional robot base frames (REP 105), tried when nothing else names the base."""

NO_SCAN_TRANSFORM_WARNING = "no transform from {base} to {scan_frame} in the bag; assuming the scan frame is the base frame"

SPIKE_WINDOW = 7
"""Samples in the running median that :func:`drop_translation_spikes` compares each sample with."""
SPIKE_SPEED_MPS = 100.0
"""A sample farther from the running median than this speed times the window's time span is a spike."""
SPIKE_MIN_M = 1.0
"""... and farther than this, so that dense samples do not make the test touchy."""


def translation_spike_mask(dynamic: TfArrays, window: int = SPIKE_WINDOW, speed_mps: float = SPIKE_SPEED_MPS,
                           min_jump_m: float = SPIKE_MIN_M) -> tuple[np.ndarray, Counter[tuple[str, str]]]:
    """Find the dynamic transforms whose translation leaps away from its neighbours and back (corrupt samples).

    Per (parent, child) edge in stamp order, a sample is dropped when its distance
    to the running median of ``window`` samples exceeds both ``min_jump_m`` and
    ``speed_mps`` times the window's time span. A median follows steps (a
    localizer's map -> odom correction), so only isolated leaps of up to
    ``window // 2`` samples are dropped, e.g. the 1e32 m odometry values a real
    TurtleBot3 bag holds. Returns the (N,) bool mask of samples to keep and the
    drop count per (parent, child) edge.
    """
    keep = np.ones(len(dynamic), dtype=bool)
    dropped: Counter[tuple[str, str]] = Counter()
    if len(dynamic) < 3:
        return keep, dropped
    parents, parent_id = np.unique(dynamic.parent.astype(str), return_inverse=True)
    children, child_id = np.unique(dynamic.child.astype(str), return_inverse=True)
    edges = parent_id.astype(np.int64) * children.size + child_id
    half = window // 2
    for edge in np.unique(edges):
        rows = np.flatnonzero(edges == edge)
        rows = rows[np.argsort(dynamic.stamp_ns[rows], kind="stable")]
        if rows.size < 3:
            continue
        xyz = dynamic.translation[rows]
        with np.errstate(invalid="ignore", over="ignore"):
            median = median_filter(xyz, size=(window, 1), mode="nearest")
            deviation = np.linalg.norm(xyz - median, axis=1)
        stamps = dynamic.stamp_ns[rows]
        k = np.arange(rows.size)
        span_s = (stamps[np.minimum(k + half, rows.size - 1)] - stamps[np.maximum(k - half, 0)]) / 1e9
        spike = deviation > np.maximum(min_jump_m, speed_mps * span_s)
        if spike.any():
            keep[rows[spike]] = False
            dropped[(str(parents[edge // children.size]), str(children[edge % children.size]))] += int(spike.sum())
    return keep, dropped


def drop_translation_spikes(dynamic: TfArrays, warnings: list[str]) -> tuple[TfArrays, np.ndarray]:
    """Remove the samples :func:`translation_spike_mask` finds, with one warning per repaired edge.

    Returns the kept transforms and the keep mask (to filter arrays aligned with
    ``dynamic``, such as arrival times); the warnings are appended to ``warnings``.
    """
    keep, dropped = translation_spike_mask(dynamic)
    for (parent, child), count in dropped.items():
        warnings.append(f"dropped {count} corrupt /tf samples {parent} -> {child} "
                        "(translation leaping away from its neighbours and back)")
    return (dynamic if keep.all() else dynamic.select(keep)), keep


def guess_base_frame(bag: BagReader, known_frames: set[str] | list[str], explicit: str | None = None) -> str | None:
    """The robot base frame: ``explicit``, else /odom's child frame, else base_footprint/base_link if known.

    Stands in for a sensor frame the bag's tf lacks (see :data:`NO_SCAN_TRANSFORM_WARNING`).
    """
    if explicit:
        return explicit
    if "/odom" in bag.topics and bag.topics["/odom"].msgtype in ODOMETRY_TYPES:
        first = next(bag.messages(["/odom"]), None)
        if first is not None:
            child = decode_odometry(first.msg).child_frame_id.lstrip("/")
            if child:
                return child
    return next((f for f in BASE_FRAME_CANDIDATES if f in known_frames), None)
