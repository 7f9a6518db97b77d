"""The batched lookup of the tf buffer: walk from both frames towards the root at every requested stamp at once,
splitting the stamps where parents or failures differ (:class:`Branch`), compose the edges up to the common
ancestor, and say why a stamp has no transform in tf2's words (:class:`Failure`). :class:`LookupWalk` is the part of
:class:`~bagtools.tf.buffer.TfBuffer` that does it."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bagtools.tf import _rigid
from bagtools.tf._rigid import Rigid
from bagtools.tf.exceptions import (
    BackwardExtrapolationException,
    ConnectivityException,
    ForwardExtrapolationException,
    LookupException,
    NoDataForExtrapolationException,
)
from bagtools.tf.track import FUTURE, OK, PAST, FrameSamples, Track, format_stamp


@dataclass
class Branch:
    """Stamps (indices into the batch) that walk up through the same frames from one start frame."""

    index: np.ndarray            # (K,) sorted indices into the batch
    frames: list[int]            # frames[0] = start, frames[k+1] = parent of frames[k]
    acc: list[Rigid]             # acc[k] = T_{frames[k]}_{start} for these stamps
    fail_frame: int = -1         # the frame whose own transform failed (the path ends there), or -1 (root)
    fail_codes: np.ndarray | None = None


@dataclass(frozen=True)
class Failure:
    """Why stamp ``position`` of a batch has no transform: enough to build tf2's message."""

    kind: str                    # "extrapolation" or "connectivity"
    stamp_ns: int
    frame: int = -1
    code: int = OK


class LookupWalk:
    """The lookup machinery of :class:`~bagtools.tf.buffer.TfBuffer`, which holds the frames (``_frames``, their
    tracks through ``_track``), the bag's path for messages (``path``) and the frames' dropped transforms
    (``invalid_note``)."""

    _frames: list[FrameSamples]
    path: str | None

    def _track(self, frame_id: int) -> Track | None:
        return self._frames[frame_id].compile()

    def _latest_chain(self, start: int) -> list[tuple[int, int | None]]:
        """[(frame, latest stamp or None if static), ...] walking up by each frame's latest parent."""
        chain: list[tuple[int, int | None]] = []
        frame = start
        while True:
            track = self._track(frame)
            if track is None:
                return chain
            chain.append((frame, None if track.static else track.last_ns))
            frame = int(track.parent[-1])
            if len(chain) > len(self._frames):
                raise LookupException("The tf tree is invalid because it contains a loop.", self.path)
            if frame == start:
                raise LookupException("The tf tree is invalid because it contains a loop.", self.path)

    def _chain_to_common(self, target_id: int, source_id: int) -> list[tuple[int, int | None]] | None:
        """The edges (child frame, latest stamp) between the two frames by latest parents; None if unconnected."""
        source_chain = self._latest_chain(source_id)
        target_chain = self._latest_chain(target_id)
        source_frames = [source_id] + [self._frame_parent_latest(f) for f, _ in source_chain]
        target_frames = [target_id] + [self._frame_parent_latest(f) for f, _ in target_chain]
        for j, frame in enumerate(target_frames):
            if frame in source_frames:
                i = source_frames.index(frame)
                return source_chain[:i] + target_chain[:j]
        return None

    def _frame_parent_latest(self, frame_id: int) -> int:
        track = self._track(frame_id)   # a frame of a chain: it has data
        return -1 if track is None else int(track.parent[-1])

    def _resolve(self, target_id: int, source_id: int, stamps: np.ndarray):
        """Compose T_target_source at every stamp: (q (4,N), t (3,N), valid (N,), {position: Failure})."""
        n = stamps.size
        q = np.zeros((4, n))
        q[3] = 1.0
        t = np.zeros((3, n))
        valid = np.zeros(n, dtype=bool)
        failure: dict[int, Failure] = {}
        if n == 0:
            return q, t, valid, failure
        if target_id == source_id:
            valid[:] = True
            return q, t, valid, failure
        everything = np.arange(n)
        source_paths = self._walk(source_id, stamps, everything)
        target_paths = self._walk(target_id, stamps, everything)
        for sp in source_paths:
            for tp in target_paths:
                if sp.index is tp.index or (sp.index.size == n and tp.index.size == n):
                    index, s_sel, t_sel = sp.index, None, None
                else:
                    index = np.intersect1d(sp.index, tp.index, assume_unique=True)
                    if index.size == 0:
                        continue
                    s_sel = np.searchsorted(sp.index, index)
                    t_sel = np.searchsorted(tp.index, index)
                common = next((f for f in tp.frames if f in sp.frames), None)
                if common is None:
                    self._record_failure(failure, index, stamps, sp, tp, s_sel, t_sel)
                    continue
                a_source = sp.acc[sp.frames.index(common)]
                a_target = tp.acc[tp.frames.index(common)]
                if s_sel is not None:
                    a_source = _rigid.take(a_source, s_sel)
                    a_target = _rigid.take(a_target, t_sel)
                result = _rigid.compose(_rigid.inverse(a_target), a_source)
                if result is not None:
                    rq, rt = result
                    if index.size == n:
                        q, t = np.broadcast_to(rq, (4, n)), np.broadcast_to(rt, (3, n))
                    else:
                        q[:, index], t[:, index] = rq, rt
                valid[index] = True
        if not (q.flags.writeable and t.flags.writeable):
            q, t = q.copy(), t.copy()
        return q, t, valid, failure

    def _record_failure(self, failure: dict[int, Failure], index: np.ndarray, stamps: np.ndarray,
                        sp: Branch, tp: Branch, s_sel, t_sel) -> None:
        # tf2's order: a failing edge on the target side, then on the source side, else not connected.
        if tp.fail_frame >= 0:
            frame, codes = tp.fail_frame, tp.fail_codes if t_sel is None else tp.fail_codes[t_sel]
        elif sp.fail_frame >= 0:
            frame, codes = sp.fail_frame, sp.fail_codes if s_sel is None else sp.fail_codes[s_sel]
        else:
            frame, codes = -1, None
        first = int(index[0])
        if frame < 0:
            failure[first] = Failure("connectivity", int(stamps[first]))
        else:
            failure[first] = Failure("extrapolation", int(stamps[first]), frame, int(codes[0]))
        # Only the first failing position of each group is needed (errors report the first failing stamp).

    def _walk(self, start: int, stamps: np.ndarray, index: np.ndarray) -> list[Branch]:
        """Walk from ``start`` towards the root at every stamp, splitting where parents or failures differ."""
        paths: list[Branch] = []
        stack: list[Branch] = [Branch(index, [start], [None])]
        while stack:
            path = stack.pop()
            frame = path.frames[-1]
            track = self._track(frame)
            if track is None:
                paths.append(path)
                continue
            sub_stamps = stamps if path.index.size == stamps.size else stamps[path.index]
            parent, edge, fail = track.evaluate(sub_stamps)
            acc = path.acc[-1]
            index = path.index
            if fail is not None:
                ok = fail == OK
                paths.append(Branch(index[~ok], path.frames, [_rigid.take(a, ~ok) for a in path.acc],
                                   frame, fail[~ok]))
                if not ok.any():
                    continue
                index, edge, acc = index[ok], _rigid.take(edge, ok), _rigid.take(acc, ok)
                accs = [_rigid.take(a, ok) for a in path.acc]
                if not isinstance(parent, int):
                    parent = parent[ok]
            else:
                accs = path.acc
            groups = [(parent, None)] if isinstance(parent, int) else \
                [(int(p), parent == p) for p in np.unique(parent)]
            for parent_id, select in groups:
                if select is not None and select.all():
                    select = None
                sub_index = index if select is None else index[select]
                sub_edge = edge if select is None else _rigid.take(edge, select)
                sub_acc = acc if select is None else _rigid.take(acc, select)
                sub_accs = accs if select is None else [_rigid.take(a, select) for a in accs]
                if parent_id in path.frames or len(path.frames) > len(self._frames):
                    raise LookupException("The tf tree is invalid because it contains a loop.", self.path)
                stack.append(Branch(sub_index, path.frames + [parent_id], sub_accs + [_rigid.compose(sub_edge, sub_acc)]))
        return paths

    # ------------------------------------------------------------------ errors

    def _connectivity(self, target_id: int, source_id: int) -> ConnectivityException:
        return ConnectivityException(
            f"Could not find a connection between '{self._frames[target_id].name}' and "
            f"'{self._frames[source_id].name}' because they are not part of the same tree."
            "Tf has two or more unconnected trees."
            + self.invalid_note(*sorted(self.invalid_dropped)), self.path)

    def _exception(self, failure: Failure, target_id: int, source_id: int):
        if failure.kind == "connectivity":
            return self._connectivity(target_id, source_id)
        track = self._track(failure.frame)   # a failing edge belongs to a frame with data
        requested = format_stamp(failure.stamp_ns)
        if failure.code == PAST:
            cls = BackwardExtrapolationException
            text = (f"Lookup would require extrapolation into the past.  Requested time {requested} "
                    f"but the earliest data is at time {format_stamp(track.first_ns)}")
        elif failure.code == FUTURE:
            cls = ForwardExtrapolationException
            text = (f"Lookup would require extrapolation into the future.  Requested time {requested} "
                    f"but the latest data is at time {format_stamp(track.last_ns)}")
        else:
            cls = NoDataForExtrapolationException
            text = (f"Lookup would require extrapolation at time {requested}, "
                    f"but only time {format_stamp(track.first_ns)} is in the buffer")
        return cls(f"{text}, when looking up transform from frame [{self._frames[source_id].name}] "
                   f"to frame [{self._frames[target_id].name}]", self.path)
