"""Accumulating transformed points into a map whose memory is bounded by the map, not the input."""

from __future__ import annotations

import numpy as np

from bagtools.errors import BagtoolsError


def random_subset(points: np.ndarray, fraction: float, rng: np.random.Generator) -> np.ndarray:
    """Keep round(fraction * N) points chosen at random without replacement (MATLAB pcdownsample 'random')."""
    n = points.shape[0]
    keep = int(round(fraction * n))
    if keep >= n:
        return points
    index = np.sort(rng.choice(n, size=keep, replace=False))
    return points[index]


#: Smallest voxel edge accepted, metres (a tenth of a millimetre: far below any sensor's noise).
MIN_VOXEL_M = 1e-4


def voxel_downsample(points: np.ndarray, voxel_m: float) -> np.ndarray:
    """Average the points in each voxel of edge ``voxel_m`` (Open3D's voxel_down_sample).

    Raises :class:`BagtoolsError` when the points span more voxels per axis
    than Open3D can index (32-bit voxel coordinates).
    """
    import open3d as o3d

    if points.shape[0] == 0:
        return points
    span_m = float(np.max(points.max(axis=0) - points.min(axis=0)))
    if not span_m / voxel_m < np.iinfo(np.int32).max:
        raise BagtoolsError(f"--voxel {voxel_m:g} m is too small for a map spanning {span_m:.4g} m "
                            f"(Open3D indexes at most {np.iinfo(np.int32).max} voxels per axis)")
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points.astype(np.float64)))
    return np.asarray(cloud.voxel_down_sample(voxel_m).points, dtype=np.float32)


class PointAccumulator:
    """Collects map points (N,3) float32 in the map frame.

    With ``voxel_m`` set, the collected points are voxel-downsampled whenever the
    pending part grows past ``compact_every`` points, so memory stays bounded by
    the number of occupied voxels.
    """

    def __init__(self, voxel_m: float | None = None, compact_every: int = 2_000_000) -> None:
        self.voxel_m = voxel_m
        self.compact_every = compact_every
        self._parts: list[np.ndarray] = []
        self._pending = 0
        self.points_added = 0

    def add(self, points_map: np.ndarray) -> None:
        """Add (N,3) points already in the map frame."""
        if points_map.shape[0] == 0:
            return
        self._parts.append(np.asarray(points_map, dtype=np.float32))
        self._pending += points_map.shape[0]
        self.points_added += points_map.shape[0]
        if self.voxel_m and self._pending > self.compact_every:
            self._parts = [voxel_downsample(np.concatenate(self._parts), self.voxel_m)]
            self._pending = 0

    def points(self) -> np.ndarray:
        """The map: (M,3) float32 (voxel-downsampled if ``voxel_m`` is set)."""
        if not self._parts:
            return np.empty((0, 3), dtype=np.float32)
        merged = np.concatenate(self._parts)
        if self.voxel_m:
            merged = voxel_downsample(merged, self.voxel_m)
            self._parts, self._pending = [merged], 0
        return merged
