"""Repairs for the tf data of real recordings, shared by every command that replays a bag.

- Corrupt samples: a real TurtleBot3 bag holds odometry at 1e22..1e32 m for a few
  samples (a serial link corrupting messages), and smaller glitches (a coordinate
  zeroed, a yaw flipped); one such sample would ruin every pose after it. Two
  publishers may also write one edge (a second odometry source near zero) or
  publish one stamp twice. :func:`repair_dynamic_tf` removes the corrupt samples
  and keeps one publisher, and says so; :func:`tf_conflicts` reports the same
  findings for ``info`` and ``tf frames``.
- A missing laser mount: some bags have no base -> scan transform; commands then
  take the scan frame to be the base frame and say so with
  :data:`NO_SCAN_TRANSFORM_WARNING`.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field

import numpy as np

from bagtools.io import ODOMETRY_TYPES, BagReader, TfArrays, decode_odometry
from bagtools.tf.buffer import MAX_TRANSLATION_M

BASE_FRAME_CANDIDATES = ("base_footprint", "base_link")
"""Conventional robot base frames (REP 105), tried when nothing else names the base."""

NO_SCAN_TRANSFORM_WARNING = "no transform from {base} to {scan_frame} in the bag; assuming the scan frame is the base frame"

SPIKE_WINDOW = 7
"""Samples in the running median that :func:`drop_translation_spikes` compares each sample with."""
SPIKE_SPEED_MPS = 100.0
"""A sample farther from the running median than this speed times the window's time span is a spike."""
SPIKE_MIN_M = 1.0
"""... and farther than this, so that dense samples do not make the test touchy."""


def _median_filter(rows: np.ndarray, window: int) -> np.ndarray:
    """Each column's running median over ``window`` rows, the ends repeated: element ``window // 2`` of the sorted
    rows i - window // 2 ... i + (window - 1) // 2, as ``scipy.ndimage.median_filter(rows, size=(window, 1),
    mode="nearest")`` gives it (without importing scipy.ndimage, 0.2 s, into every command that reads tf)."""
    rows = np.asarray(rows)
    if len(rows) == 0:
        return rows.copy()
    before, after = window // 2, window - 1 - window // 2
    padded = np.concatenate([np.repeat(rows[:1], before, axis=0), rows, np.repeat(rows[-1:], after, axis=0)])
    windows = np.lib.stride_tricks.sliding_window_view(padded, window, axis=0)  # (N, cols, window)
    return np.partition(windows, window // 2, axis=-1)[..., window // 2]


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
    for edge, rows in _edges(dynamic).items():
        leaps = _leaps(dynamic.stamp_ns[rows], dynamic.translation[rows], window, speed_mps, min_jump_m)
        if leaps.size:
            keep[rows[leaps]] = False
            dropped[edge] += int(leaps.size)
    return keep, dropped


def _leaps(stamps_ns: np.ndarray, xyz: np.ndarray, window: int = SPIKE_WINDOW, speed_mps: float = SPIKE_SPEED_MPS,
           min_jump_m: float = SPIKE_MIN_M) -> np.ndarray:
    """Rows (of one edge, in stamp order) that leap away from the running median faster than anything moves."""
    n = stamps_ns.size
    if n < 3:
        return np.zeros(0, dtype=np.int64)
    with np.errstate(invalid="ignore", over="ignore"):
        deviation = np.linalg.norm(xyz - _median_filter(xyz, window), axis=1)
    half = window // 2
    k = np.arange(n)
    span_s = (stamps_ns[np.minimum(k + half, n - 1)] - stamps_ns[np.maximum(k - half, 0)]) / 1e9
    return np.flatnonzero(deviation > np.maximum(min_jump_m, speed_mps * span_s))


def _angle_between(q1: np.ndarray, q2: np.ndarray) -> np.ndarray:
    """Rotation angle (rad) between unit quaternions (N,4) (either order, any sign)."""
    dot = np.abs(np.einsum("ij,ij->i", q1, q2))
    return 2.0 * np.arccos(np.clip(dot, 0.0, 1.0))


def _unit(q: np.ndarray) -> np.ndarray:
    with np.errstate(invalid="ignore", divide="ignore"):
        return q / np.linalg.norm(q, axis=1, keepdims=True)


@dataclass
class EdgeFindings:
    """What :func:`inspect_edge` found on one dynamic (parent, child) edge; ``drop`` indexes rows of the edge."""

    stray: int = 0  # samples stamped far from all the others (an unset clock: 1 ns)
    repeated: int = 0  # samples at a stamp the edge already had
    conflicting: int = 0  # ... of which with another value
    interleaved: str = ""  # a description of two interleaved publishers, and which one is kept
    corrupt: int = 0  # leaps faster than anything moves (1e30 m values)
    glitches: int = 0  # short runs far from the samples around them, which agree
    jumps: int = 0  # steps faster than anything moves that do not come back (said, not repaired)
    largest_jump_m: float = 0.0
    drop: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))


#: A sample farther than this (or this many times the edge's typical nonzero step) from the running median,
#: in a short run whose neighbours agree, is a glitch.
GLITCH_MIN_M = 0.05
GLITCH_MIN_RAD = 0.1
GLITCH_STEP_FACTOR = 5.0
#: Glitches that form a coherent path of their own (at least this many) are a second publisher, as are
#: glitches on more than INTERLEAVED_SHARE of an edge's samples.
MIN_STREAM_SAMPLES = 10
INTERLEAVED_SHARE = 0.25


def inspect_edge(stamps_ns: np.ndarray, translation: np.ndarray, rotation_xyzw: np.ndarray,
                 publishers: np.ndarray | None = None) -> EdgeFindings:
    """Repeated stamps, interleaved publishers, corrupt leaps and glitches on one edge (rows in stamp order).

    In this order, each step on the samples the previous ones kept:

    - Where the bag names each sample's publisher (``publishers``: a ROS 1
      connection's callerid) and two nodes publish the edge, the streams are
      told apart by name, whatever their rates, and the one that moves over
      the larger extent is kept.

    - A stamp seen before keeps its first sample (tf2 ignores repeated data);
      it is a conflict when the values differ.
    - Two publishers interleaved on the edge show as "glitches" that form a
      coherent path of their own (consecutive ones close together, far from
      the other samples), or as a path that zig-zags between alternate samples:
      the two streams are told apart and the one that moves over the larger
      extent is kept.
    - Corrupt leaps (:func:`_leaps`: 1e30 m values) are dropped.
    - A step faster than SPIKE_SPEED_MPS that does not come back (the whole
      frame moved: an odometry reset, a localizer's jump, damage) is counted as
      a jump and said; it is not repaired, as nothing tells which side is right.
    - A glitch is a short run of samples (up to 3) far from the running median
      (more than GLITCH_MIN_M / GLITCH_MIN_RAD, and GLITCH_STEP_FACTOR times the
      edge's typical nonzero step) while the samples on either side of the run
      agree: a zeroed coordinate, a flipped yaw. A localizer's step correction is
      not one: the samples around it disagree.
    """
    n = stamps_ns.size
    found = EdgeFindings()
    rows = _without_stray_stamps(stamps_ns)
    found.stray = n - rows.size
    if publishers is not None:
        named = _split_by_publisher(stamps_ns[rows], translation[rows], np.asarray(publishers)[rows])
        if named is not None:
            kept, found.interleaved = named
            rows = rows[kept]
    repeated = rows[np.flatnonzero(stamps_ns[rows][1:] == stamps_ns[rows][:-1]) + 1]
    if repeated.size:
        first = np.searchsorted(stamps_ns, stamps_ns[repeated], side="left")
        with np.errstate(invalid="ignore", over="ignore"):  # inf - inf: not equal either
            differ = ~(np.linalg.norm(translation[repeated] - translation[first], axis=1) <= 1e-6) | (
                _angle_between(_unit(rotation_xyzw[repeated]), _unit(rotation_xyzw[first])) > 1e-6)
        found.repeated, found.conflicting = int(repeated.size), int(differ.sum())
        rows = np.setdiff1d(rows, repeated)
    if rows.size >= 5 and not found.interleaved:
        t, q = translation[rows], _sign_aligned(_unit(rotation_xyzw[rows]))
        odd = _glitches(t, q)
        second = _second_stream(stamps_ns[rows], t, odd)
        if not second and _alternating(t):  # strict turns: every other sample is the other publisher's
            odd, second = np.arange(1, rows.size, 2), True
        if second:
            kept, found.interleaved = _split_streams(stamps_ns[rows], t, odd)
            rows = rows[kept]
    leaps = _leaps(stamps_ns[rows], translation[rows])
    found.corrupt = int(leaps.size)
    rows = np.delete(rows, leaps)
    if rows.size >= 5:
        glitch = _glitches(translation[rows], _sign_aligned(_unit(rotation_xyzw[rows])))
        found.glitches = int(glitch.size)
        rows = np.delete(rows, glitch)
    with np.errstate(invalid="ignore"):  # NaN, inf and far-off values are the buffer's to refuse
        finite = rows[(np.abs(translation[rows]) <= MAX_TRANSLATION_M).all(axis=1)]
    if finite.size >= 2:
        step_m = np.linalg.norm(np.diff(translation[finite], axis=0), axis=1)
        dt_s = np.diff(stamps_ns[finite]) / 1e9
        with np.errstate(over="ignore", invalid="ignore"):
            jump = step_m > SPIKE_SPEED_MPS * dt_s + SPIKE_MIN_M
        found.jumps = int(jump.sum())
        found.largest_jump_m = float(step_m[jump].max()) if found.jumps else 0.0
    found.drop = np.setdiff1d(np.arange(n), rows)
    return found


#: A sample at the start or end of an edge more than this far in time from the rest is a stray stamp...
STRAY_GAP_S = 3600.0
#: ... or more than this many times the edge's median time step (and at least 60 s) away.
STRAY_GAP_STEPS = 1000.0


def _without_stray_stamps(stamps_ns: np.ndarray) -> np.ndarray:
    """Rows (in stamp order) except leading or trailing samples separated from the rest by a huge gap."""
    n = stamps_ns.size
    rows = np.arange(n)
    if n < 5:
        return rows
    gaps = np.diff(stamps_ns) / 1e9
    limit = min(STRAY_GAP_S, max(60.0, STRAY_GAP_STEPS * float(np.median(gaps))))
    big = np.flatnonzero(gaps > limit)
    lo, hi = 0, n
    for g in big.tolist():  # a handful of gaps at most: the edges of the series
        if g + 1 <= 2:
            lo = max(lo, g + 1)
        elif g >= n - 3:
            hi = min(hi, g + 1)
    return rows[lo:hi]


def _sign_aligned(q: np.ndarray) -> np.ndarray:
    """Quaternions flipped to the hemisphere of their predecessor (q and -q are one rotation)."""
    out = q.copy()
    flip = np.einsum("ij,ij->i", out[1:], out[:-1]) < 0
    sign = np.where(np.cumsum(flip) % 2 == 1, -1.0, 1.0)
    out[1:] *= sign[:, None]
    return out


def _glitches(t: np.ndarray, q: np.ndarray, window: int = SPIKE_WINDOW, max_run: int = 3) -> np.ndarray:
    """Rows of short runs (up to ``max_run``) that leave the running median while the samples around the run agree."""
    with np.errstate(invalid="ignore", over="ignore"):
        step_t = np.linalg.norm(np.diff(t, axis=0), axis=1)
        step_r = _angle_between(q[1:], q[:-1])
        limit_t = max(GLITCH_MIN_M, GLITCH_STEP_FACTOR * _typical_step(step_t))
        limit_r = max(GLITCH_MIN_RAD, GLITCH_STEP_FACTOR * _typical_step(step_r))
        dev_t = np.linalg.norm(t - _median_filter(t, window), axis=1)
        q_med = _unit(_median_filter(q, window))
        dev_r = _angle_between(q, q_med)
    off = (dev_t > limit_t) | (dev_r > limit_r)
    if not off.any():
        return np.zeros(0, dtype=np.int64)
    edges = np.diff(np.concatenate(([0], off.astype(np.int8), [0])))
    starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)  # run = rows start..end-1
    out = []
    for start, end in zip(starts.tolist(), ends.tolist()):  # a loop over runs, not samples
        if end - start > max_run or start == 0 or end == len(t):
            continue
        before, after = start - 1, end
        agree_t = np.linalg.norm(t[after] - t[before]) <= max(limit_t, dev_t[start:end].max() / 4)
        agree_r = _angle_between(q[after:after + 1], q[before:before + 1])[0] <= max(limit_r, dev_r[start:end].max() / 4)
        if agree_t and agree_r:
            out.extend(range(start, end))
    return np.asarray(out, dtype=np.int64)


def _typical_step(steps: np.ndarray) -> float:
    """The median of the steps that move at all: a localizer holding its pose between corrections has many zero
    steps, and its corrections, not the zeros, are what a glitch must stand out from."""
    moving = steps[steps > 1e-9]
    return float(np.median(moving)) if moving.size else 0.0


def _second_stream(stamps_ns: np.ndarray, t: np.ndarray, odd: np.ndarray) -> bool:
    """Whether the glitch rows ``odd`` are another publisher's samples rather than damage."""
    if odd.size < MIN_STREAM_SAMPLES:
        return False
    if odd.size > INTERLEAVED_SHARE * t.shape[0]:
        return True
    main = np.setdiff1d(np.arange(t.shape[0]), odd)
    nearest = main[np.clip(np.searchsorted(stamps_ns[main], stamps_ns[odd]), 0, main.size - 1)]
    with np.errstate(invalid="ignore", over="ignore"):
        to_main = float(np.nanmedian(np.linalg.norm(t[odd] - t[nearest], axis=1)))
        along = float(np.nanmedian(np.linalg.norm(np.diff(t[odd], axis=0), axis=1)))
    return along < 0.25 * to_main


def _alternating(t: np.ndarray) -> bool:
    """Two publishers taking turns: the path zig-zags far more than its even and odd samples each move."""
    with np.errstate(invalid="ignore", over="ignore"):
        whole = float(np.nansum(np.linalg.norm(np.diff(t, axis=0), axis=1)))
        halves = sum(float(np.nansum(np.linalg.norm(np.diff(t[k::2], axis=0), axis=1))) for k in (0, 1))
    return whole > 1.0 and whole > 4.0 * halves


def _split_by_publisher(stamps_ns: np.ndarray, t: np.ndarray, publishers: np.ndarray
                        ) -> tuple[np.ndarray, str] | None:
    """Two nodes publishing one edge, by the names the bag gives (None for one node, or a second with fewer
    than MIN_STREAM_SAMPLES samples): the rows kept and a description naming both."""
    names, counts = np.unique(publishers.astype(str), return_counts=True)
    ranked = [(int(c), str(name)) for name, c in zip(names, counts) if name]
    ranked.sort(reverse=True)
    if len(ranked) < 2 or ranked[1][0] < MIN_STREAM_SAMPLES:
        return None
    first = ranked[0][1]
    others = [name for _, name in ranked[1:]]
    odd = np.flatnonzero(publishers.astype(str) != first)
    return _split_streams(stamps_ns, t, odd, names=(" and ".join(others), first))


def _split_streams(stamps_ns: np.ndarray, t: np.ndarray, odd: np.ndarray,
                   names: tuple[str, str] | None = None) -> tuple[np.ndarray, str]:
    """Two interleaved streams: the ``odd`` rows and the rest (``names``: their publishers, when known).

    Returns the rows of the stream kept (the one whose positions span more) and a description.
    """
    n = stamps_ns.size
    a = np.zeros(n, dtype=bool)
    a[odd] = True
    streams = [np.flatnonzero(a), np.flatnonzero(~a)]

    def span_m(rows: np.ndarray) -> float:  # robust: a few samples of the other stream may be mixed in
        if not rows.size:
            return 0.0
        lo, hi = np.nanpercentile(t[rows], [5, 95], axis=0)
        return float(np.linalg.norm(hi - lo))

    def rate_hz(rows: np.ndarray) -> float:
        dur = (stamps_ns[rows[-1]] - stamps_ns[rows[0]]) / 1e9 if rows.size > 1 else 0.0
        return (rows.size - 1) / dur if dur > 0 else 0.0

    labels = {0: "", 1: ""} if names is None else {0: f" of {names[0]}", 1: f" of {names[1]}"}
    order = sorted(range(2), key=lambda k: span_m(streams[k]), reverse=True)
    kept, dropped = streams[order[0]], streams[order[1]]
    who = "" if names is None else f" ({names[0]} and {names[1]}, by the bag's callerids)"
    far = ""
    if kept.size and dropped.size:
        gap = np.nanmedian(np.linalg.norm(t[dropped] - t[kept[np.clip(np.searchsorted(kept, dropped), 0,
                                                                           kept.size - 1)]], axis=1))
        far = f"; the two are {gap:.3g} m apart"
    text = (f"two publishers interleaved{who}: kept {kept.size} samples{labels[order[0]]} "
            f"({rate_hz(kept):.1f} Hz, spanning {span_m(kept):.3g} m), dropped {dropped.size}{labels[order[1]]} "
            f"({rate_hz(dropped):.1f} Hz, spanning {span_m(dropped):.3g} m){far}")
    return kept, text


def repair_dynamic_tf(dynamic: TfArrays, warnings: list[str]) -> tuple[TfArrays, np.ndarray]:
    """The repairs every command applies to recorded /tf, with one warning per repaired edge and kind.

    Per edge, :func:`inspect_edge`'s findings are dropped. Returns the kept
    transforms and the keep mask (to filter arrays aligned with ``dynamic``,
    such as arrival times).
    """
    keep = np.ones(len(dynamic), dtype=bool)
    for (parent, child), rows in _edges(dynamic).items():
        found = inspect_edge(dynamic.stamp_ns[rows], dynamic.translation[rows], dynamic.rotation_xyzw[rows],
                             None if dynamic.publisher is None else dynamic.publisher[rows])
        keep[rows[found.drop]] = False
        warnings.extend(describe_findings(parent, child, found, repaired=True))
    return (dynamic if keep.all() else dynamic.select(keep)), keep


def describe_findings(parent: str, child: str, found: EdgeFindings, repaired: bool) -> list[str]:
    """One line per kind of finding on the edge (``repaired``: say what was dropped)."""
    out = []
    edge = f"/tf {parent} -> {child}"
    if found.stray:
        out.append(f"{edge}: {'dropped ' if repaired else ''}{found.stray} sample(s) stamped far from all the others "
                   "(an unset clock?)")
    if found.conflicting:
        out.append(f"{edge}: {found.conflicting} stamp(s) published twice with different values "
                   f"(two publishers?){'; kept the first of each' if repaired else ''}")
    elif found.repeated and repaired:
        out.append(f"{edge}: ignored {found.repeated} repeated sample(s) at a stamp already seen")
    if found.interleaved:
        text = found.interleaved if repaired else (found.interleaved.replace(": kept", ": the mapping commands use")
                                                   .replace(", dropped", ", not"))
        out.append(f"{edge}: {text}")
    if found.corrupt:
        out.append(f"dropped {found.corrupt} corrupt /tf samples {parent} -> {child} "
                   "(translation leaping away from its neighbours and back)" if repaired else
                   f"{edge}: {found.corrupt} corrupt sample(s) (translation leaping away and back)")
    if found.glitches:
        out.append(f"{edge}: {'dropped ' if repaired else ''}{found.glitches} isolated glitch(es) (samples far from "
                   "those around them, which agree: a zeroed coordinate or a flipped yaw)")
    if found.jumps:
        out.append(f"{edge}: jumps {found.jumps} time(s), up to {found.largest_jump_m:.3g} m at once, faster than "
                   f"{SPIKE_SPEED_MPS:g} m/s, and stays there (a reset, or damage): whatever is placed through "
                   "this edge after a jump is that far off")
    return out


def _edges(dynamic: TfArrays, keep: np.ndarray | None = None) -> dict[tuple[str, str], np.ndarray]:
    """(parent, child) -> row indexes in stamp order (stable), leading '/' stripped; rows not in ``keep`` left out."""
    if len(dynamic) == 0:
        return {}
    parents = np.array([p.lstrip("/") for p in dynamic.parent.astype(str)], dtype=object)
    children = np.array([c.lstrip("/") for c in dynamic.child.astype(str)], dtype=object)
    pairs = np.char.add(np.char.add(parents.astype(str), "\x1f"), children.astype(str))
    names, inverse = np.unique(pairs, return_inverse=True)
    out = {}
    for k, name in enumerate(names):
        rows = np.flatnonzero(inverse == k)
        if keep is not None:
            rows = rows[keep[rows]]
        rows = rows[np.argsort(dynamic.stamp_ns[rows], kind="stable")]
        parent, child = str(name).split("\x1f")
        out[(parent, child)] = rows
    return out


def parent_conflicts(dynamic: TfArrays | None, static: TfArrays | None) -> list[str]:
    """One line per frame published with more than one parent (on /tf, on /tf_static, or across them)."""
    parents_of: dict[str, dict[str, set[str]]] = {}
    for arrays, topic in ((dynamic, "/tf"), (static, "/tf_static")):
        if arrays is None or not len(arrays):
            continue
        for parent, child in set(zip(arrays.parent.astype(str).tolist(), arrays.child.astype(str).tolist())):
            parents_of.setdefault(child.lstrip("/"), {}).setdefault(parent.lstrip("/"), set()).add(topic)
    out = []
    for child, parents in sorted(parents_of.items()):
        if len(parents) > 1:
            named = ", ".join(f"{p} on {' and '.join(sorted(t))}" for p, t in sorted(parents.items()))
            out.append(f"frame {child} has {len(parents)} parents ({named}); tf2 keeps one at a time, so lookups "
                       "through it depend on which was published last")
    return out + static_value_conflicts(static)


#: Two static samples of one edge differ when their translations are this far apart (m) or rotations this much (rad).
STATIC_TOLERANCE_M, STATIC_TOLERANCE_RAD = 1e-4, 1e-4


def static_value_conflicts(static: TfArrays | None) -> list[str]:
    """One line per /tf_static edge given more than one value (two static publishers, or a mount changed while
    recording): tf2 keeps the value set last, so data placed through the edge is off by their difference."""
    out: list[str] = []
    if static is None or not len(static):
        return out
    for (parent, child), rows in _edges(static).items():
        rows = rows[np.isfinite(static.translation[rows]).all(axis=1) & np.isfinite(static.rotation_xyzw[rows]).all(axis=1)]
        if rows.size < 2:  # non-finite samples are refused where the buffer reads them
            continue
        t, q = static.translation[rows], static.rotation_xyzw[rows]
        q = q / np.maximum(np.linalg.norm(q, axis=1, keepdims=True), 1e-12)
        last = rows.size - 1  # rows are in stamp order, ties in bag order: the buffer keeps this one
        dist_m = np.linalg.norm(t - t[last], axis=1)
        angle_rad = 2.0 * np.arccos(np.clip(np.abs(q @ q[last]), 0.0, 1.0))
        differ = (dist_m > STATIC_TOLERANCE_M) | (angle_rad > STATIC_TOLERANCE_RAD)
        if differ.any():
            out.append(f"/tf_static gives {parent} -> {child} {int(differ.sum()) + 1} different values (up to "
                       f"{dist_m.max():.3g} m and {np.degrees(angle_rad.max()):.3g} deg apart); the one set last is "
                       f"used ({', '.join(f'{v:.3g}' for v in t[last])} m), as tf2 keeps it: data placed through "
                       "this edge may be off by that much")
    return out


def tf_conflicts(dynamic: TfArrays, static: TfArrays) -> list[str]:
    """What is wrong with a bag's tf, for ``info`` and ``tf frames``: frames with two parents, and per edge
    what :func:`repair_dynamic_tf` would repair (conflicting stamps, interleaved publishers, corrupt samples,
    glitches, stray stamps)."""
    out = parent_conflicts(dynamic, static)
    for (parent, child), rows in _edges(dynamic).items():
        found = inspect_edge(dynamic.stamp_ns[rows], dynamic.translation[rows], dynamic.rotation_xyzw[rows],
                             None if dynamic.publisher is None else dynamic.publisher[rows])
        out.extend(describe_findings(parent, child, found, repaired=False))
    return out


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
