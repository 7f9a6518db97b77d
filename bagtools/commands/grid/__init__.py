"""Occupancy-grid maps of a bag's laser scans at known poses (``bagtools grid``)."""

from bagtools.commands.grid.writer import GRID_MAP_FILES, write_grid_map
from bagtools.grid.options import MAX_GRID_CELLS, GridMapOptions
from bagtools.grid.pipeline import GridMapPipeline, GridMapResult

__all__ = [
    "GRID_MAP_FILES", "MAX_GRID_CELLS", "GridMapOptions", "GridMapPipeline", "GridMapResult", "write_grid_map",
]
