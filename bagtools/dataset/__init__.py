"""The sensor data of a bag as a dataset: decoded, checked, counted, and posed (see :mod:`bagtools.dataset.scans`); a
bag's laser scans with its odometry and the laser's mount, as a front end takes them (:mod:`bagtools.dataset.laser`)."""

from bagtools.dataset.poses import (
    NO_SCAN_TRANSFORM_WARNING,
    ScanPoseSource,
    TfScanPoses,
    TrajectoryScanPoses,
)
from bagtools.dataset.scans import (
    LOGGING_ORDER_STEP_NS,
    PosedScan,
    ScanClock,
    ScanMessage,
    ScanStream,
    SensorPoints,
    SensorStream,
    posed_scan_chunks,
    recording_order,
    require_topic,
    scan_clock,
    stamped_late,
)

from bagtools.dataset.laser import LaserDataset, ScanInputs  # noqa: E402  (after scans: it imports them)

__all__ = [
    "LaserDataset", "ScanInputs",
    "LOGGING_ORDER_STEP_NS", "NO_SCAN_TRANSFORM_WARNING", "PosedScan", "ScanClock", "ScanMessage", "ScanPoseSource", "ScanStream", "SensorPoints",
    "SensorStream", "TfScanPoses", "TrajectoryScanPoses", "posed_scan_chunks", "recording_order", "require_topic", "scan_clock",
    "stamped_late",
]
