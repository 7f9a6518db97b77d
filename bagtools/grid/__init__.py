"""Probabilistic occupancy grids from laser scans at known poses.

- :class:`OccupancyGrid` (``occupancy``): log-odds grid with MATLAB occupancyMap
  conventions (``world2grid``, ``grid2world``, ``get_occupancy``,
  ``check_occupancy``, ``insert_ray``), growing when data falls outside it.
- ``raytrace``: the exact, vectorized grid traversal behind ``insert_ray``.
- ``mapio``: nav2 / map_server PGM + YAML writer and reader, PNG renderer.
- ``score``: rasterized truth and map-vs-truth scores.
"""

from bagtools.grid.mapio import (
    Nav2Map,
    nav2_map_files,
    read_nav2_map,
    render_map_png,
    write_map_png,
    write_nav2_map,
)
from bagtools.grid.occupancy import OccupancyGrid
from bagtools.grid.raytrace import Traversal, traverse
from bagtools.grid.score import MapScore, rasterize_truth, score_map

__all__ = [
    "MapScore",
    "Nav2Map",
    "OccupancyGrid",
    "Traversal",
    "nav2_map_files",
    "rasterize_truth",
    "read_nav2_map",
    "render_map_png",
    "score_map",
    "traverse",
    "write_map_png",
    "write_nav2_map",
]
