"""Point-cloud maps from known poses (``bagtools map-cloud``)."""

from bagtools.cloudmap.accumulator import PointAccumulator, random_subset, voxel_downsample
from bagtools.cloudmap.pipeline import CloudMapOptions, CloudMapPipeline, CloudMapResult
from bagtools.cloudmap.writer import CLOUD_MAP_FILES, write_cloud_map

__all__ = [
    "CLOUD_MAP_FILES", "CloudMapOptions", "CloudMapPipeline", "CloudMapResult", "PointAccumulator",
    "random_subset", "voxel_downsample", "write_cloud_map",
]
