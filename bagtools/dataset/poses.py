"""Where each scan was taken: the scan frame's pose in the map's frame, batched over scan stamps.

Two kinds of source, one interface (:class:`ScanPoseSource`):

- :class:`TfScanPoses`: the bag's tf, ``T_frame_scan`` looked up at the scan stamps;
- :class:`TrajectoryScanPoses`: a trajectory of the robot base in the frame
  (``/ground_truth`` or a TUM file), interpolated at the scan stamps as tf does
  (it is held in its own :class:`~bagtools.tf.TfBuffer`), composed with the bag's
  base -> scan transform.

A scan frame the bag's tf does not know (a real TurtleBot3 bag has no
base_link -> base_scan transform) is taken to be the base frame, with the
warning :data:`NO_SCAN_TRANSFORM_WARNING`.
"""

from __future__ import annotations

from enum import StrEnum
from typing import Protocol

import numpy as np

from bagtools.errors import BagtoolsError
from bagtools.tf import TfBuffer, TransformException
from bagtools.tf.repair import NO_SCAN_TRANSFORM_WARNING
from bagtools.transforms import quat2xyzw, tform2quat


class NoPose(StrEnum):
    """Why a scan has no pose (the counts of skipped scans say these words)."""

    UNKNOWN_FRAME = "scan frame not in tf"
    NOT_CONNECTED = "frames not connected"
    BEFORE = "before pose data"
    AFTER = "after pose data"
    NO_POSE = "no pose at stamp"


class ScanPoseSource(Protocol):
    """Poses of a body frame in the map's frame at arrays of stamps."""

    frame: str
    warnings: list[str]

    def lookup(self, body_frame: str, stamps_ns: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(T_frame_body (N,4,4), reasons (N,) object array: '' where the pose is known, else why not)."""
        ...


def _reasons_by_span(valid: np.ndarray, stamps_ns: np.ndarray, span: tuple[int, int] | None) -> np.ndarray:
    """'' where valid; otherwise before/after the span of the pose data, or 'no pose at stamp'."""
    reasons = np.full(stamps_ns.shape, "", dtype=object)
    bad = ~valid
    if not bad.any():
        return reasons
    reasons[bad] = NoPose.NO_POSE
    if span is not None:
        reasons[bad & (stamps_ns < span[0])] = NoPose.BEFORE
        reasons[bad & (stamps_ns > span[1])] = NoPose.AFTER
    return reasons


def _tf_lookup(buffer: TfBuffer, target: str, source: str, stamps_ns: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """T_target_source (N,4,4) at ``stamps_ns`` and the reasons (see :class:`ScanPoseSource`); never raises for tf failures."""
    n = stamps_ns.size
    if not (buffer.has_frame(target) and buffer.has_frame(source)):
        return np.full((n, 4, 4), np.nan), np.full(n, NoPose.UNKNOWN_FRAME, dtype=object)
    try:
        span = buffer.time_range(target, source)
    except TransformException:
        return np.full((n, 4, 4), np.nan), np.full(n, NoPose.NOT_CONNECTED, dtype=object)
    T, valid = buffer.lookup(target, source, stamps_ns, return_mask=True)
    return T, _reasons_by_span(valid, stamps_ns, span)


class TfScanPoses:
    """Scan poses from the bag's tf: T_frame_scan = lookup(frame, scan frame, stamp).

    When the scan frame is not in tf, ``base_frame`` stands in for it (warned once per frame).
    With ``T_base_scan`` (4,4) (the laser mount, given by the user), T_frame_scan =
    lookup(frame, base_frame, stamp) @ T_base_scan.
    """

    def __init__(self, buffer: TfBuffer, frame: str, base_frame: str | None,
                 T_base_scan: np.ndarray | None = None) -> None:
        self.buffer = buffer
        self.frame = frame
        self.base_frame = base_frame
        self.T_base_scan = T_base_scan
        self.warnings: list[str] = []

    def lookup(self, body_frame: str, stamps_ns: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        if self.T_base_scan is not None and self.base_frame:  # the mount is given: the base's pose from tf
            T, reasons = _tf_lookup(self.buffer, self.frame, self.base_frame, np.asarray(stamps_ns, dtype=np.int64))
            return T @ self.T_base_scan, reasons
        source = body_frame
        if not self.buffer.has_frame(body_frame) and self.base_frame and self.buffer.has_frame(self.base_frame):
            _warn_once(self.warnings, NO_SCAN_TRANSFORM_WARNING.format(base=self.base_frame, scan_frame=body_frame))
            source = self.base_frame
        return _tf_lookup(self.buffer, self.frame, source, np.asarray(stamps_ns, dtype=np.int64))


class TrajectoryScanPoses:
    """Scan poses from a base trajectory in ``frame``, composed with the bag's base -> scan transform.

    Args:
        stamps_ns: (N,) int ns of the trajectory samples.
        T_frame_base: (N,4,4) poses of ``base_frame`` in ``frame``.
        frame, base_frame: frame ids (they must differ).
        buffer: the bag's tf, for T_base_scan (may be empty: the scan frame is then the base).
    """

    def __init__(self, stamps_ns: np.ndarray, T_frame_base: np.ndarray, frame: str, base_frame: str,
                 buffer: TfBuffer, T_base_scan: np.ndarray | None = None) -> None:
        if frame == base_frame:
            raise BagtoolsError(f"the trajectory's base frame must differ from --frame, both are {frame!r}")
        self.frame = frame
        self.base_frame = base_frame
        self.buffer = buffer
        self.T_base_scan = T_base_scan
        self.warnings: list[str] = []
        T_frame_base = np.asarray(T_frame_base, dtype=np.float64)
        self._trajectory = TfBuffer()
        self._trajectory.set_transform(frame, base_frame, np.asarray(stamps_ns, dtype=np.int64),
                                       T_frame_base[:, :3, 3], quat2xyzw(tform2quat(T_frame_base)))
        self.span = self._trajectory.time_range(frame, base_frame)

    def lookup(self, body_frame: str, stamps_ns: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        stamps_ns = np.asarray(stamps_ns, dtype=np.int64)
        T_frame_base, valid = self._trajectory.lookup(self.frame, self.base_frame, stamps_ns, return_mask=True)
        reasons = _reasons_by_span(valid, stamps_ns, self.span)
        if self.T_base_scan is not None:
            return T_frame_base @ self.T_base_scan, reasons
        if body_frame == self.base_frame:
            return T_frame_base, reasons
        if not (self.buffer.has_frame(body_frame) and self.buffer.has_frame(self.base_frame)):
            _warn_once(self.warnings, NO_SCAN_TRANSFORM_WARNING.format(base=self.base_frame, scan_frame=body_frame))
            return T_frame_base, reasons
        T_base_body, body_reasons = _tf_lookup(self.buffer, self.base_frame, body_frame, stamps_ns)
        reasons = np.where(reasons == "", body_reasons, reasons)
        return T_frame_base @ T_base_body, reasons


def _warn_once(warnings: list[str], text: str) -> None:
    if text not in warnings:
        warnings.append(text)
