"""Point-cloud maps from known poses (``bagtools map-cloud``)."""

from bagtools.cloudmap.accumulator import (
    MapCloud, PointAccumulator, random_indices, random_subset, voxel_average, voxel_downsample,
)
from bagtools.cloudmap.files import write_point_cloud
from bagtools.cloudmap.pipeline import CloudMapOptions, CloudMapPipeline, CloudMapResult, PlacedInput
from bagtools.cloudmap.writer import CLOUD_MAP_FILES, write_cloud_map

__all__ = [
    "CLOUD_MAP_FILES", "CloudMapOptions", "CloudMapPipeline", "CloudMapResult", "MapCloud", "PlacedInput",
    "PointAccumulator", "random_indices", "random_subset", "voxel_average", "voxel_downsample", "write_cloud_map",
    "write_point_cloud",
]
