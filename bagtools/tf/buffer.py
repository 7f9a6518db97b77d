"""The tf buffer: tf2's BufferCore semantics over whole recordings, vectorized over stamps.

Frames form a tree (each child has one parent at a time). Every child frame
keeps its samples as sorted arrays; a lookup walks from both frames to their
common ancestor at each requested time, interpolating every edge (translation
linearly, rotation by shortest-path slerp between the two neighbouring samples,
as tf2) and composing the edges, for all requested stamps at once.

tf2 behaviour kept on purpose:

- a stamp equal to a sample returns that sample; no extrapolation before the
  first or after the last sample; a frame with one sample is valid only at its
  stamp; static transforms are valid at every time;
- ``stamp_ns=None`` means tf2's "latest common time": the minimum over the
  latest stamps of the dynamic transforms on the path (statics ignored);
- a frame may change parent over time: the parent at time t is the one of the
  newest sample at or before t, and there is no interpolation across a change;
- out-of-order samples are sorted in; samples with equal stamps keep the one
  set last (exact duplicates are thereby dropped); a leading '/' is stripped
  from frame ids when set and rejected when looked up; setting a static
  transform on a dynamic frame (or the reverse) replaces its data, as tf2 does;
- the error types and messages are tf2's (see :mod:`bagtools.tf.exceptions`).

Differences: nothing is pruned by age (offline use wants the whole bag), a
stamp of 0 is an ordinary time (``None`` asks for the latest), and the result
is composed over the path to the common ancestor only, which is what tf2's
walk to the root reduces to.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from bagtools.tf import _rigid
from bagtools.tf.exceptions import (
    ConnectivityException,
    ExtrapolationException,
    InvalidArgumentException,
    LookupException,
)
from bagtools.tf.track import FrameSamples, Track, as_stamps, compose_up, format_stamp, strip_ids
from bagtools.tf.walk import Failure, LookupWalk

# tf2's tolerance on | |q|^2 - 1 | for an accepted quaternion.
QUATERNION_NORMALIZATION_TOLERANCE = 10e-3

#: A transform whose translation is farther than this on any axis is damage, not data, and is invalid like a NaN
#: (no robot's frame is a million kilometres from its parent: ECEF and UTM coordinates stay below 1e7 m). Past some
#: 1e14 m a metre no longer shows in a float64 sum and past 3.4e38 m a float32 point is infinite, so such a
#: transform would collapse a map, a grid or a picture to no extent (or a NaN one) wherever it is used.
MAX_TRANSLATION_M = 1.0e9

# Stamps resolved per block of a batch lookup (sized for the CPU cache).
_BLOCK = 1 << 15


class TfBuffer(LookupWalk):
    """A tf2-style transform buffer over recorded transforms, with vectorized lookups.

    Example::

        buf = TfBuffer.from_bag("run.mcap")
        T_map_base = buf.lookup("map", "base_link", stamps_ns)   # (N, 4, 4)
        p_map = T_map_base[:, :3, :3] @ p_base + T_map_base[:, :3, 3]
    """

    def __init__(self) -> None:
        self._ids: dict[str, int] = {}
        self._frames: list[FrameSamples] = []
        self.path: str | None = None       # the bag the buffer came from, for error messages
        self.warnings: list[str] = []      # transforms skipped by from_bag / from_arrays(skip_invalid=True)
        self.invalid_dropped: dict[str, int] = {}   # frame -> transforms of it skipped as invalid (NaN, far off, zero quaternion)
        self.bag_span_ns: tuple[int, int] | None = None   # (start_ns, end_ns) of the bag, set by from_bag
        self._chains: dict[tuple[int, int], tuple[list[Track], list[Track]] | None] = {}  # one-stamp fast path

    # ------------------------------------------------------------------ loading

    @classmethod
    def from_bag(cls, path: str | Path) -> TfBuffer:
        """Load /tf and /tf_static of any bag (MCAP, rosbag2 sqlite3, ROS 1).

        Corrupt samples (isolated translation leaps, as real odometry sometimes
        records) are dropped, and transforms tf2 would ignore (NaN, non-unit
        quaternion, empty frame id, frame equal to its parent) are skipped; both
        are counted in ``warnings``,
        after the reader's own warnings (e.g. a truncated MCAP read up to the cut).
        Raises :class:`~bagtools.errors.BagError` if the bag cannot be read.
        """
        from bagtools.io import open_bag, read_tf_arrays

        with open_bag(path) as bag:
            dynamic, static = read_tf_arrays(bag)
            source, span, reader_warnings = bag.path, (bag.start_ns, bag.end_ns), list(bag.warnings)
        buffer = cls.from_arrays(dynamic, static, skip_invalid=True, repair_spikes=True)
        buffer.warnings[:0] = reader_warnings
        buffer.path = str(source)
        buffer.bag_span_ns = span
        return buffer

    @classmethod
    def from_arrays(cls, dynamic, static=None, skip_invalid: bool = False, repair_spikes: bool = False) -> TfBuffer:
        """A buffer from :class:`~bagtools.io.TfArrays` of /tf (``dynamic``) and /tf_static (``static``).

        Statics are set first, then the dynamic transforms, so a frame published
        on both topics ends up dynamic. With ``skip_invalid`` bad transforms are
        skipped (and counted in ``warnings``) instead of raising. With
        ``repair_spikes`` corrupt samples of recorded data (isolated translation
        leaps, see :mod:`bagtools.tf.repair`) are dropped first, with a warning.
        """
        buffer = cls()
        if repair_spikes and dynamic is not None:
            from bagtools.tf.repair import repair_dynamic_tf

            dynamic = repair_dynamic_tf(dynamic, buffer.warnings)[0]
        if skip_invalid:
            from bagtools.tf.repair import parent_conflicts

            buffer.warnings.extend(parent_conflicts(dynamic, static))
        for arrays, is_static in ((static, True), (dynamic, False)):
            if arrays is not None and len(arrays):
                buffer._set(arrays.parent, arrays.child, arrays.stamp_ns, arrays.translation, arrays.rotation_xyzw,
                            is_static, skip_invalid)
        return buffer

    def set_transform(self, parent: str | Sequence[str] | np.ndarray, child: str | Sequence[str] | np.ndarray,
                      stamp_ns: int | np.ndarray, translation: np.ndarray, rotation_xyzw: np.ndarray,
                      static: bool = False) -> None:
        """Add the pose of ``child`` in ``parent`` (T_parent_child) at ``stamp_ns``.

        One transform (str, str, int, (3,), (4,)) or N of them ((N,) frame ids or
        one id for all, (N,) int ns, (N,3) metres, (N,4) quaternions in ROS order
        x, y, z, w). Raises :class:`InvalidArgumentException` for empty frame ids,
        a child equal to its parent, NaN or infinite values, a translation beyond
        :data:`MAX_TRANSLATION_M` on an axis, quaternions whose
        squared norm is off 1 by 0.01 or more, or non-integer stamps; nothing is
        added then.
        """
        self._set(parent, child, stamp_ns, translation, rotation_xyzw, static, skip_invalid=False)

    def _set(self, parent, child, stamp_ns, translation, rotation_xyzw, static: bool, skip_invalid: bool) -> None:
        stamps = as_stamps(stamp_ns, "stamp_ns")
        n = stamps.size
        trans = np.asarray(translation, dtype=np.float64).reshape(-1, 3) if np.size(translation) else np.empty((0, 3))
        rot = np.asarray(rotation_xyzw, dtype=np.float64).reshape(-1, 4) if np.size(rotation_xyzw) else np.empty((0, 4))
        if np.shape(translation)[-1:] != (3,) or np.shape(rotation_xyzw)[-1:] != (4,) or trans.shape[0] != n \
                or rot.shape[0] != n:
            raise InvalidArgumentException(
                f"set_transform needs N stamps, (N,3) translations and (N,4) rotations; got {np.shape(stamp_ns)}, "
                f"{np.shape(translation)} and {np.shape(rotation_xyzw)}", self.path)
        parents = strip_ids(parent, n)
        children = strip_ids(child, n)
        bad = np.zeros(n, dtype=bool)
        reasons: list[tuple[np.ndarray, str]] = [
            (parents == "", "frame_id (parent) is empty"),
            (children == "", "child_frame_id is empty"),
            (parents == children, "frame_id and child_frame_id are the same"),
            (~np.isfinite(trans).all(axis=1) | ~np.isfinite(rot).all(axis=1), "NaN or infinite value"),
        ]
        with np.errstate(invalid="ignore"):
            reasons.append(((np.abs(trans) > MAX_TRANSLATION_M).any(axis=1),
                            f"translation beyond {MAX_TRANSLATION_M:g} m"))
            norm_sq = np.einsum("ni,ni->n", rot, rot)
        reasons.append((~(np.abs(norm_sq - 1.0) < QUATERNION_NORMALIZATION_TOLERANCE) & np.isfinite(norm_sq),
                        "quaternion is not normalized"))
        for mask, reason in reasons:
            new = mask & ~bad
            if not new.any():
                continue
            i = int(np.flatnonzero(new)[0])
            parent, child = str(parents[i]), str(children[i])  # quoted as text, not as numpy's np.str_(...)
            if not skip_invalid:
                raise InvalidArgumentException(
                    f"invalid transform {parent!r} -> {child!r} "
                    f"at {format_stamp(int(stamps[i]))}: {reason}", self.path)
            self.warnings.append(f"skipped {int(new.sum())} transform(s) ({reason}), "
                                 f"e.g. {parent!r} -> {child!r} at {format_stamp(int(stamps[i]))}")
            for name in set(children[new].tolist()) | set(parents[new].tolist()):
                if name:
                    count = int(np.count_nonzero((children[new] == name) | (parents[new] == name)))
                    self.invalid_dropped[name] = self.invalid_dropped.get(name, 0) + count
            bad |= new
        if bad.any():
            keep = ~bad
            stamps, trans, rot, parents, children = stamps[keep], trans[keep], rot[keep], parents[keep], children[keep]
        if stamps.size == 0:
            return
        rot = rot / np.sqrt(np.einsum("ni,ni->n", rot, rot))[:, None]
        parent_names, parent_index = np.unique(parents, return_inverse=True)
        parent_ids = np.array([self._id(str(p)) for p in parent_names], dtype=np.int64)[parent_index.reshape(-1)]
        names, inverse = np.unique(children, return_inverse=True)
        for k, name in enumerate(names):
            rows = np.flatnonzero(inverse == k)
            frame = self._frames[self._id(str(name))]
            if frame.static is not None and frame.static != static:
                frame.chunks, frame.track = [], None   # tf2 replaces the cache when the kind changes
            frame.static = static
            frame.chunks.append((stamps[rows], parent_ids[rows], rot[rows].T, trans[rows].T, frame.inserted))
            frame.inserted += 1
        self._chains.clear()  # the tree may have changed

    def _id(self, name: str) -> int:
        frame_id = self._ids.get(name)
        if frame_id is None:
            frame_id = self._ids[name] = len(self._frames)
            self._frames.append(FrameSamples(name))
        return frame_id

    # ------------------------------------------------------------------ queries about frames

    @property
    def frames(self) -> list[str]:
        """Every frame id the buffer knows (children and parents), sorted."""
        return sorted(self._ids)

    def has_frame(self, frame: str) -> bool:
        """Whether ``frame`` was seen as a child or a parent."""
        return frame in self._ids

    def is_static(self, frame: str) -> bool | None:
        """True/False if ``frame`` has static/dynamic data, None if it is only a parent (a root)."""
        return self._frames[self._check_id(frame, "is_static argument frame")].static

    def parent(self, frame: str, stamp_ns: int | None = None) -> str | None:
        """The parent of ``frame`` at ``stamp_ns`` (latest if None); None for a root or outside its data."""
        track = self._track(self._check_id(frame, "parent argument frame"))
        if track is None:
            return None
        if stamp_ns is None:
            return self._frames[int(track.parent[-1])].name
        parent_ids, _, fail = track.evaluate(np.array([int(stamp_ns)], dtype=np.int64))
        if fail is not None:
            return None
        return self._frames[int(np.atleast_1d(parent_ids)[0])].name

    def frame_time_range(self, frame: str) -> tuple[int, int] | None:
        """(first_ns, last_ns) of the samples of ``frame`` to its parent; None if static or a root."""
        track = self._track(self._check_id(frame, "frame_time_range argument frame"))
        if track is None or track.static:
            return None
        return track.first_ns, track.last_ns

    # ------------------------------------------------------------------ validation

    def _check_id(self, frame: str, argument: str) -> int:
        self._check_format(frame, argument)
        frame_id = self._ids.get(frame)
        if frame_id is None:
            raise LookupException(f"\"{frame}\" passed to {argument} does not exist{self.invalid_note(frame)}. "
                                  f"{self._known_frames()}", self.path)
        return frame_id

    def _check_format(self, frame: str, argument: str) -> None:
        if not isinstance(frame, str) or frame == "":
            raise InvalidArgumentException(
                f"Invalid argument \"{frame}\" passed to {argument} - in tf2 frame_ids cannot be empty", self.path)
        if frame.startswith("/"):
            raise InvalidArgumentException(
                f"Invalid argument \"{frame}\" passed to {argument} - in tf2 frame_ids cannot start with a '/'",
                self.path)

    def invalid_note(self, *frames: str) -> str:
        """Why a frame may be missing or cut off: its transforms were invalid and dropped when loading."""
        notes = [f"{self.invalid_dropped[f]} transform(s) of '{f}' were invalid (NaN, infinite, beyond "
                 f"{MAX_TRANSLATION_M:g} m or a zero quaternion) and dropped" for f in frames if self.invalid_dropped.get(f)]
        return f" ({'; '.join(notes)})" if notes else ""

    def _known_frames(self) -> str:
        names = self.frames
        if not names:
            return "The buffer has no frames."
        shown = ", ".join(names[:30]) + (f" and {len(names) - 30} more" if len(names) > 30 else "")
        return f"Known frames: {shown}."

    def latest_common_time(self, target: str, source: str) -> int | None:
        """tf2's latest common time of the path between two frames, int ns; None if the path is all static.

        The minimum of the latest stamps of the dynamic transforms between each
        frame and the common ancestor (following each frame's latest parent).
        Raises LookupException / ConnectivityException as ``lookup`` does.
        """
        target_id = self._check_id(target, "latest_common_time argument target_frame")
        source_id = self._check_id(source, "latest_common_time argument source_frame")
        if target_id == source_id:
            track = self._track(target_id)
            return None if track is None or track.static else track.last_ns
        edges = self._chain_to_common(target_id, source_id)
        if edges is None:
            raise self._connectivity(target_id, source_id)
        stamps = [s for _, s in edges if s is not None]
        return min(stamps) if stamps else None

    def chain_edges(self, target: str, source: str) -> list[tuple[str, str]]:
        """The (parent, child) edges between two frames up to their common ancestor, by latest parents.

        Raises LookupException / ConnectivityException as ``lookup`` does.
        """
        target_id = self._check_id(target, "chain_edges argument target_frame")
        source_id = self._check_id(source, "chain_edges argument source_frame")
        if target_id == source_id:
            return []
        edges = self._chain_to_common(target_id, source_id)
        if edges is None:
            raise self._connectivity(target_id, source_id)
        return [(self._frames[self._frame_parent_latest(f)].name, self._frames[f].name) for f, _ in edges]

    def time_range(self, target: str, source: str) -> tuple[int, int] | None:
        """(first_ns, last_ns) over which every dynamic transform between the frames has data; None if all static.

        Follows each frame's latest parent (as the latest common time does). The
        range may be empty (first > last) when the transforms never overlap.
        """
        target_id = self._check_id(target, "time_range argument target_frame")
        source_id = self._check_id(source, "time_range argument source_frame")
        edges = [] if target_id == source_id else self._chain_to_common(target_id, source_id)
        if edges is None:
            raise self._connectivity(target_id, source_id)
        tracks = [self._track(f) for f, s in edges if s is not None]
        if target_id == source_id:
            track = self._track(target_id)
            tracks = [] if track is None or track.static else [track]
        if not tracks:
            return None
        return max(t.first_ns for t in tracks), min(t.last_ns for t in tracks)

    # ------------------------------------------------------------------ lookups

    def lookup(self, target: str, source: str, stamp_ns: int | np.ndarray | None = None,
               return_mask: bool = False):
        """T_target_source: the 4x4 matrix with p_target = T @ p_source (the pose of source in target).

        As tf2's lookupTransform(target, source, time). ``stamp_ns``: int ns ->
        (4,4); (N,) int ns -> (N,4,4); None -> tf2's latest common time, (4,4).
        Raises LookupException (unknown frame), ConnectivityException,
        ExtrapolationException (time outside the data; the first failing stamp
        is reported) or InvalidArgumentException. With ``return_mask=True``
        returns (T, valid) instead of raising for stamps without a transform:
        valid is a bool array shaped like the stamps and invalid rows are NaN.
        """
        if not return_mask and isinstance(stamp_ns, (int, np.integer)) and not isinstance(stamp_ns, bool):
            one = self._lookup_one(target, source, int(stamp_ns))
            if one is not None:
                return one
        q, t, valid, single, failure, ids = self._lookup_rigid(target, source, stamp_ns, "lookupTransform")
        n = valid.size
        matrices = _rigid.to_matrices((q, t), n)
        return self._finish(matrices, valid, single, failure, ids, return_mask)

    # ------------------------------------------------------------------ one stamp

    def _lookup_one(self, target: str, source: str, stamp_ns: int) -> np.ndarray | None:
        """T_target_source (4,4) at one stamp on plain floats, or None where the batched path must decide (an
        unknown or malformed frame, a parent that changes over time, no data at the stamp: it raises tf2's
        errors). :meth:`Track.at` and the scalar twins of :mod:`bagtools.tf._rigid`, without the array machinery."""
        chain = self._chain(target, source)
        if chain is None:
            return None
        a = compose_up(chain[0], stamp_ns)
        b = compose_up(chain[1], stamp_ns)
        if a is None or b is None:
            return None
        return _rigid.matrix_one(_rigid.compose_one(_rigid.inverse_one(b), a))

    def _chain(self, target: str, source: str) -> tuple[list[Track], list[Track]] | None:
        """The tracks from ``source`` and from ``target`` up to their common ancestor, when every one has a
        parent that never changes (cached until the buffer changes); None otherwise."""
        target_id, source_id = self._ids.get(target), self._ids.get(source)
        if target_id is None or source_id is None or target_id == source_id:
            return None
        key = (target_id, source_id)
        if key in self._chains:
            return self._chains[key]
        paths = []
        for start in (source_id, target_id):
            frames, tracks, frame = [start], [], start
            while True:
                track = self._track(frame)
                if track is None:
                    break
                parent = int(track.parent[0]) if track.static else track.only_parent
                if parent < 0 or parent in frames or len(frames) > len(self._frames):
                    frames = None
                    break
                frames.append(parent)
                tracks.append(track)
                frame = parent
            if frames is None:
                self._chains[key] = None
                return None
            paths.append((frames, tracks))
        (s_frames, s_tracks), (t_frames, t_tracks) = paths
        common = next((f for f in t_frames if f in s_frames), None)
        chain = None if common is None else (s_tracks[:s_frames.index(common)], t_tracks[:t_frames.index(common)])
        self._chains[key] = chain
        return chain

    def lookup_pose(self, target: str, source: str, stamp_ns: int | np.ndarray | None = None,
                    return_mask: bool = False):
        """As :meth:`lookup` but returns (translation (N,3) metres, rotation (N,4) ROS order x, y, z, w).

        One stamp (or None) gives (3,) and (4,). With ``return_mask`` a third
        item, the valid mask, is returned. Rotations have w >= 0.
        """
        q, t, valid, single, failure, ids = self._lookup_rigid(target, source, stamp_ns, "lookupTransform")
        q = q * np.where(q[3] < 0.0, -1.0, 1.0)
        translation, rotation = self._finish((t.T, q.T), valid, single, failure, ids, return_mask=True)[0]
        if return_mask:
            return translation, rotation, (valid[0] if single else valid)
        self._raise_first(valid, failure, ids)
        return translation, rotation

    def lookup_full(self, target: str, target_stamp_ns: int | np.ndarray | None, source: str,
                    source_stamp_ns: int | np.ndarray | None, fixed: str, return_mask: bool = False):
        """tf2's time-travel lookup: T mapping p_source at source_stamp to p_target at target_stamp.

        Equals lookup(target, fixed, target_stamp) @ lookup(fixed, source,
        source_stamp): ``fixed`` is a frame assumed not to move (e.g. odom or
        map). Stamps as in :meth:`lookup`; an array and a scalar broadcast.
        """
        for frame, argument in ((target, "target_frame"), (source, "source_frame"), (fixed, "fixed_frame")):
            self._check_id(frame, f"lookupTransform argument {argument}")
        t_target_fixed = self.lookup(target, fixed, target_stamp_ns, return_mask)
        t_fixed_source = self.lookup(fixed, source, source_stamp_ns, return_mask)
        if not return_mask:
            return t_target_fixed @ t_fixed_source
        (a, valid_a), (b, valid_b) = t_target_fixed, t_fixed_source
        return a @ b, valid_a & valid_b

    def can_transform(self, target: str, source: str, stamp_ns: int | np.ndarray | None = None):
        """Whether :meth:`lookup` would succeed: a bool, or a bool array for an array of stamps.

        Never raises for unknown or malformed frames (returns False), as tf2's canTransform.
        """
        if target == source and isinstance(target, str) and target and not target.startswith("/"):
            return True if stamp_ns is None or np.ndim(stamp_ns) == 0 else np.ones(np.shape(stamp_ns), dtype=bool)
        try:
            valid = self.lookup(target, source, stamp_ns, return_mask=True)[1]
            return bool(valid) if np.ndim(valid) == 0 else valid
        except (LookupException, InvalidArgumentException, ConnectivityException, ExtrapolationException):
            return False if stamp_ns is None or np.ndim(stamp_ns) == 0 else np.zeros(np.shape(stamp_ns), dtype=bool)

    def can_transform_full(self, target: str, target_stamp_ns: int | np.ndarray | None, source: str,
                           source_stamp_ns: int | np.ndarray | None, fixed: str):
        """Whether :meth:`lookup_full` would succeed (bool or bool array); never raises for bad frames."""
        a = self.can_transform(target, fixed, target_stamp_ns)
        b = self.can_transform(fixed, source, source_stamp_ns)
        return np.logical_and(a, b) if np.ndim(a) or np.ndim(b) else bool(a and b)

    # ------------------------------------------------------------------ internals of a lookup

    def _lookup_rigid(self, target: str, source: str, stamp_ns, api: str):
        if target == source:  # tf2: the identity, whether or not the buffer knows the frame
            self._check_format(target, f"{api} argument target_frame")
            stamps = np.zeros(1, dtype=np.int64) if stamp_ns is None else as_stamps(stamp_ns, "stamp_ns")
            n = stamps.size
            q = np.zeros((4, n))
            q[3] = 1.0
            return q, np.zeros((3, n)), np.ones(n, dtype=bool), stamp_ns is None or np.ndim(stamp_ns) == 0, {}, (0, 0)
        target_id = self._check_id(target, f"{api} argument target_frame")
        source_id = self._check_id(source, f"{api} argument source_frame")
        single = stamp_ns is None or np.ndim(stamp_ns) == 0
        if stamp_ns is None:
            latest = None if target_id == source_id else self.latest_common_time(target, source)
            stamps = np.array([0 if latest is None else latest], dtype=np.int64)
        else:
            stamps = as_stamps(stamp_ns, "stamp_ns")
        if stamps.size <= _BLOCK:
            q, t, valid, failure = self._resolve(target_id, source_id, stamps)
        else:  # blocks that stay in cache are ~2x faster than one pass over 10^6 stamps
            q, t = np.empty((4, stamps.size)), np.empty((3, stamps.size))
            valid = np.empty(stamps.size, dtype=bool)
            failure = {}
            for start in range(0, stamps.size, _BLOCK):
                stop = min(start + _BLOCK, stamps.size)
                q[:, start:stop], t[:, start:stop], valid[start:stop], block_failure = \
                    self._resolve(target_id, source_id, stamps[start:stop])
                failure.update({start + k: f for k, f in block_failure.items()})
        return q, t, valid, single, failure, (target_id, source_id)

    def _finish(self, values, valid: np.ndarray, single: bool, failure: dict[int, Failure], ids, return_mask: bool):
        if not return_mask:
            self._raise_first(valid, failure, ids)
        elif not valid.all():
            if isinstance(values, tuple):
                for v in values:
                    v[~valid] = np.nan
            else:
                values[~valid] = np.nan
        if single:
            values = tuple(v[0] for v in values) if isinstance(values, tuple) else values[0]
            valid = valid[0]
        return (values, valid) if return_mask else values

    def _raise_first(self, valid: np.ndarray, failure: dict[int, Failure], ids) -> None:
        if valid.all():
            return
        position = int(np.flatnonzero(~valid)[0])
        raise self._exception(failure[position], *ids)
