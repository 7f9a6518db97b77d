"""The laser scans of a bag with their poses: the dataset iterator of the grid mapper.

Scans are read in bag order and posed in chunks, so each chunk's pose lookup
is one vectorized call per scan frame and memory stays bounded by the chunk.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from bagtools.gridmap.poses import ScanPoseSource
from bagtools.io import LASERSCAN_TYPES, BagReader, LaserScanArrays, decode_laserscan
from bagtools.progress import progress

CHUNK_SCANS = 256
"""Scans posed per batch lookup."""


@dataclass(frozen=True)
class PosedScan:
    """One scan and where it was taken.

    ``T_frame_scan`` (4,4) is the scan frame's pose in the map's frame (NaN when
    unknown); ``skip_reason`` is '' when the pose is known, else why not.
    """

    scan: LaserScanArrays
    T_frame_scan: np.ndarray
    skip_reason: str


def _pose_chunk(scans: list[LaserScanArrays], poses: ScanPoseSource) -> list[PosedScan]:
    stamps = np.array([s.stamp_ns for s in scans], dtype=np.int64)
    frames = np.array([s.frame_id for s in scans], dtype=object)
    T = np.empty((len(scans), 4, 4))
    reasons = np.empty(len(scans), dtype=object)
    for frame_id in dict.fromkeys(frames):
        rows = np.flatnonzero(frames == frame_id)
        T[rows], reasons[rows] = poses.lookup(str(frame_id), stamps[rows])
    return [PosedScan(scan, T[i], str(reasons[i])) for i, scan in enumerate(scans)]


def iter_posed_scan_chunks(bag: BagReader, topic: str, poses: ScanPoseSource,
                           chunk_scans: int = CHUNK_SCANS) -> Iterator[list[PosedScan]]:
    """Yield the LaserScans of ``topic`` with their poses, in bag order, ``chunk_scans`` at a time.

    Shows a progress bar. Raises :class:`~bagtools.errors.TopicError` if the
    topic is missing or not a LaserScan topic.
    """
    info = bag.require_topic(topic, LASERSCAN_TYPES)
    chunk: list[LaserScanArrays] = []
    for rec in progress(bag.messages([topic]), total=info.count, desc="grid", unit="scan"):
        chunk.append(decode_laserscan(rec.msg))
        if len(chunk) == chunk_scans:
            yield _pose_chunk(chunk, poses)
            chunk = []
    if chunk:
        yield _pose_chunk(chunk, poses)
