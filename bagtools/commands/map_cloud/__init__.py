"""Point-cloud maps from known poses (``bagtools map-cloud``)."""

from bagtools.commands.map_cloud.files import write_point_cloud
from bagtools.commands.map_cloud.pipeline import CloudMapOptions, CloudMapPipeline, CloudMapResult, PlacedInput
from bagtools.commands.map_cloud.writer import CLOUD_MAP_FILES, write_cloud_map

__all__ = [
    "CLOUD_MAP_FILES", "CloudMapOptions", "CloudMapPipeline", "CloudMapResult", "PlacedInput", "write_cloud_map",
    "write_point_cloud",
]
