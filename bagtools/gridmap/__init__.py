"""Occupancy-grid maps of a bag's laser scans at known poses (``bagtools grid``)."""

from bagtools.gridmap.options import MAX_GRID_CELLS, GridMapOptions
from bagtools.gridmap.pipeline import GridMapPipeline, GridMapResult
from bagtools.gridmap.poses import NO_SCAN_TRANSFORM_WARNING, ScanPoseSource, TfScanPoses, TrajectoryScanPoses
from bagtools.gridmap.scans import PosedScan, iter_posed_scan_chunks
from bagtools.gridmap.writer import GRID_MAP_FILES, write_grid_map

__all__ = [
    "GRID_MAP_FILES", "MAX_GRID_CELLS", "NO_SCAN_TRANSFORM_WARNING", "GridMapOptions", "GridMapPipeline",
    "GridMapResult", "PosedScan", "ScanPoseSource", "TfScanPoses", "TrajectoryScanPoses", "iter_posed_scan_chunks",
    "write_grid_map",
]
