"""The sensor data of a bag as a dataset: decoded, checked, counted, and posed (see :mod:`bagtools.dataset.scans`)."""

from bagtools.dataset.poses import (
    NO_SCAN_TRANSFORM_WARNING,
    ScanPoseSource,
    TfScanPoses,
    TrajectoryScanPoses,
)
from bagtools.dataset.scans import (
    PosedScan,
    ScanMessage,
    ScanStream,
    SensorPoints,
    SensorStream,
    posed_scan_chunks,
    recording_order,
    require_topic,
    stamped_late,
)

__all__ = [
    "NO_SCAN_TRANSFORM_WARNING", "PosedScan", "ScanMessage", "ScanPoseSource", "ScanStream", "SensorPoints",
    "SensorStream", "TfScanPoses", "TrajectoryScanPoses", "posed_scan_chunks", "recording_order", "require_topic", "stamped_late",
]
