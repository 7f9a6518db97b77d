"""Point clouds as data: a map's cloud (:class:`MapCloud`, points with their attributes), its accumulation and
voxel filters. ``map-cloud`` builds maps of them; ``ndt-odom`` writes its scans' cloud with them."""

from bagtools.cloud.accumulator import (
    MapCloud, PointAccumulator, random_indices, random_subset, voxel_average, voxel_downsample,
)

__all__ = ["MapCloud", "PointAccumulator", "random_indices", "random_subset", "voxel_average", "voxel_downsample"]
