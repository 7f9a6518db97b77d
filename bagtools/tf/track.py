"""What the tf buffer (:mod:`bagtools.tf.buffer`) keeps of each child frame: its samples as sorted arrays
(:class:`Track`), interpolated at many stamps at once as tf2 does (translation linearly, rotation by shortest-path
slerp, no extrapolation, no interpolation across a change of parent), and the chunks set since the last lookup
(:class:`FrameSamples`); plus the parsing of stamps and frame ids that setting a transform needs."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from bagtools.tf import _rigid
from bagtools.tf._rigid import Rigid
from bagtools.tf.exceptions import InvalidArgumentException

#: Why a track has no transform at a stamp: none (OK), before its first sample (PAST), after its last (FUTURE),
#: or away from the only sample it has (SINGLE).
OK, PAST, FUTURE, SINGLE = 0, 1, 2, 3


def format_stamp(stamp_ns: int) -> str:
    """Seconds with 6 decimals, as tf2's displayTimePoint (rounded from exact int ns)."""
    sign = "-" if stamp_ns < 0 else ""
    micros = (abs(int(stamp_ns)) + 500) // 1000
    return f"{sign}{micros // 1_000_000}.{micros % 1_000_000:06d}"


@dataclass
class Track:
    """The compiled samples of one child frame (M samples, M-1 intervals)."""

    stamps: np.ndarray        # (M,) int64, strictly increasing
    parent: np.ndarray        # (M,) int64 frame ids
    q: np.ndarray             # (4, M) unit quaternions x, y, z, w
    t: np.ndarray             # (3, M) metres
    static: bool
    duration: np.ndarray = field(init=False)       # (M-1,) float64 ns between neighbours
    q_next: np.ndarray = field(init=False)         # (4, M-1) q[:, j+1], sign-flipped onto q[:, j]'s hemisphere
    omega_over_pi: np.ndarray = field(init=False)  # (M-1,) angle between the quaternions / pi
    same_parent: np.ndarray = field(init=False)    # (M-1,) bool: interpolation allowed
    only_parent: int = field(init=False)           # the parent if it never changes, else -1

    def __post_init__(self) -> None:
        self.duration = np.diff(self.stamps).astype(np.float64)
        q0, q1 = self.q[:, :-1], self.q[:, 1:]
        dot = np.einsum("im,im->m", q0, q1)
        sign = np.where(dot < 0.0, -1.0, 1.0)
        self.q_next = q1 * sign
        self.omega_over_pi = np.arccos(np.clip(dot * sign, -1.0, 1.0)) / np.pi
        self.same_parent = self.parent[:-1] == self.parent[1:]
        self.only_parent = int(self.parent[0]) if bool(np.all(self.parent == self.parent[0])) else -1

    @property
    def first_ns(self) -> int:
        return int(self.stamps[0])

    @property
    def last_ns(self) -> int:
        return int(self.stamps[-1])

    def evaluate(self, stamps: np.ndarray) -> tuple[np.ndarray | int, Rigid, np.ndarray | None]:
        """The edge at ``stamps`` (N,): (parent ids (N,) or one int, T_parent_child, failure codes (N,) or None)."""
        if self.static:
            return int(self.parent[0]), (self.q[:, :1], self.t[:, :1]), None
        m = self.stamps.size
        if m == 1:
            fail = np.where(stamps == self.stamps[0], OK, SINGLE).astype(np.int8)
            return int(self.parent[0]), (self.q[:, :1], self.t[:, :1]), (fail if fail.any() else None)
        fail = None
        if stamps.size == 0:
            return self.only_parent if self.only_parent >= 0 else stamps.copy(), (self.q[:, :0], self.t[:, :0]), None
        if stamps[0] < self.stamps[0] or stamps[-1] > self.stamps[-1] or not is_sorted(stamps):
            codes = np.where(stamps < self.stamps[0], PAST, np.where(stamps > self.stamps[-1], FUTURE, OK))
            if codes.any():
                fail = codes.astype(np.int8)
        # interval j: stamps[j] <= t <= stamps[j+1] (clipped so failing stamps still index safely)
        j = np.searchsorted(self.stamps, stamps, side="right") - 1
        np.clip(j, 0, m - 2, out=j)
        alpha = (stamps - self.stamps[j]).astype(np.float64) / self.duration[j]
        if fail is not None:
            np.clip(alpha, 0.0, 1.0, out=alpha)
        if self.only_parent >= 0:
            parent: np.ndarray | int = self.only_parent
        else:
            # Across a parent change tf2 returns the older sample (or the newer one at its exact stamp).
            alpha = np.where(self.same_parent[j], alpha, np.floor(alpha))
            parent = np.where(alpha >= 1.0, self.parent[j + 1], self.parent[j])
        w0, w1 = _rigid.slerp_weights(alpha, self.omega_over_pi[j])
        q = self.q[:, j] * w0 + self.q_next[:, j] * w1
        t = self.t[:, j] * (1.0 - alpha) + self.t[:, j + 1] * alpha
        return parent, (q, t), fail


    def at(self, stamp_ns: int) -> tuple[list[float], list[float]] | None:
        """T_parent_child (q, t) on plain floats at one stamp, as :meth:`evaluate` gives it for a track whose
        parent never changes; None where :meth:`evaluate` reports a failure (no data at the stamp)."""
        m = self.stamps.size
        if self.static or (m == 1 and stamp_ns == self.stamps[0]):
            return self.q[:, 0].tolist(), self.t[:, 0].tolist()
        if m == 1 or stamp_ns < self.stamps[0] or stamp_ns > self.stamps[-1]:
            return None
        j = min(max(int(np.searchsorted(self.stamps, stamp_ns, side="right")) - 1, 0), m - 2)
        alpha = float(stamp_ns - int(self.stamps[j])) / float(self.duration[j])
        w0, w1 = _rigid.slerp_weights_one(alpha, float(self.omega_over_pi[j]))
        q0, q1 = self.q[:, j].tolist(), self.q_next[:, j].tolist()
        t0, t1 = self.t[:, j].tolist(), self.t[:, j + 1].tolist()
        return [a * w0 + b * w1 for a, b in zip(q0, q1)], [a * (1.0 - alpha) + b * alpha for a, b in zip(t0, t1)]


def is_sorted(stamps: np.ndarray) -> bool:
    return bool(stamps.size < 2 or np.all(stamps[1:] >= stamps[:-1]))


@dataclass
class FrameSamples:
    """A frame id and (if it is ever a child) its samples: pending chunks and their compiled track."""

    name: str
    static: bool | None = None      # None: only ever seen as a parent (no data of its own)
    chunks: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, int]] = field(default_factory=list)
    track: Track | None = None
    inserted: int = 0               # running insertion counter (ties on stamps keep the last set)

    def compile(self) -> Track | None:
        """Merge pending chunks into the sorted track and return it."""
        if not self.chunks:
            return self.track
        parts = self.chunks
        if self.track is not None:
            old = self.track
            parts = [(old.stamps, old.parent, old.q, old.t, -1)] + parts
        stamps = np.concatenate([p[0] for p in parts])
        parent = np.concatenate([p[1] for p in parts])
        q = np.concatenate([p[2] for p in parts], axis=1)
        t = np.concatenate([p[3] for p in parts], axis=1)
        order_key = np.concatenate([np.full(p[0].size, p[4], dtype=np.int64) for p in parts])
        sequence = np.concatenate([np.arange(p[0].size) for p in parts])
        self.chunks = []
        if self.static:
            last = int(np.lexsort((sequence, order_key))[-1])  # a static frame holds the transform set last
            keep = np.array([last])
        else:
            order = np.lexsort((sequence, order_key, stamps))
            sorted_stamps = stamps[order]
            last_of_run = np.ones(order.size, dtype=bool)
            last_of_run[:-1] = sorted_stamps[1:] != sorted_stamps[:-1]
            keep = order[last_of_run]
        self.track = Track(stamps[keep], parent[keep], np.ascontiguousarray(q[:, keep]),
                            np.ascontiguousarray(t[:, keep]), bool(self.static))
        return self.track


def compose_up(tracks: list[Track], stamp_ns: int) -> tuple | None:
    """T_top_start (q, t) on plain floats composed up ``tracks`` (start frame first) at one stamp; None where a
    track has no data there."""
    acc = ([0.0, 0.0, 0.0, 1.0], [0.0, 0.0, 0.0])
    for track in tracks:
        edge = track.at(stamp_ns)
        if edge is None:
            return None
        acc = _rigid.compose_one(edge, acc)
    return acc


def as_stamps(stamp_ns, name: str) -> np.ndarray:
    """(N,) int64 from an int or an integer array; raises InvalidArgumentException for floats."""
    arr = np.asarray(stamp_ns)
    if arr.dtype == object and arr.size:
        try:
            arr = arr.astype(np.int64)
        except (TypeError, ValueError, OverflowError) as exc:
            raise InvalidArgumentException(f"{name} must be integer nanoseconds, got {arr.dtype}") from exc
    if arr.size and not np.issubdtype(arr.dtype, np.integer):
        raise InvalidArgumentException(f"{name} must be integer nanoseconds (int64), got {arr.dtype}")
    if arr.ndim > 1:
        raise InvalidArgumentException(f"{name} must be one stamp or a 1-D array, got shape {arr.shape}")
    return arr.astype(np.int64, copy=False).reshape(-1)


def strip_ids(ids, n: int) -> np.ndarray:
    """(n,) str array of frame ids with one leading '/' removed (one id is repeated n times)."""
    if isinstance(ids, str):
        stripped = ids[1:] if ids.startswith("/") else ids
        return np.full(n, stripped, dtype=object)
    arr = np.asarray(ids, dtype=object).reshape(-1)
    if arr.size != n:
        raise InvalidArgumentException(f"got {arr.size} frame ids for {n} transforms")
    return np.array([s[1:] if s.startswith("/") else s for s in arr.astype(str)], dtype=object)
