"""Accumulating transformed points (and what the sensor gave with them) into a map whose memory is bounded by the map."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bagtools.errors import BagtoolsError


@dataclass(frozen=True)
class MapCloud:
    """Points (N,3) float32 and, when every input had them, ``intensity`` (N,) float32 and ``rgb`` (N,3) uint8."""

    points: np.ndarray
    intensity: np.ndarray | None = None
    rgb: np.ndarray | None = None

    def __len__(self) -> int:
        return int(self.points.shape[0])

    def select(self, index: np.ndarray) -> MapCloud:
        """The points at ``index`` (an index array or a bool mask), attributes alike."""
        return MapCloud(self.points[index], None if self.intensity is None else self.intensity[index],
                        None if self.rgb is None else self.rgb[index])

    @property
    def fields(self) -> list[str]:
        """The point fields, as a PointCloud2 or PCD names them: x y z [intensity] [rgb]."""
        return ["x", "y", "z"] + (["intensity"] if self.intensity is not None else []) + (
            ["rgb"] if self.rgb is not None else [])


def random_indices(n: int, fraction: float, rng: np.random.Generator) -> np.ndarray | None:
    """Sorted indices of round(fraction * n) of n items chosen at random without replacement; None keeps all."""
    keep = int(round(fraction * n))
    if keep >= n:
        return None
    return np.sort(rng.choice(n, size=keep, replace=False))


def random_subset(points: np.ndarray, fraction: float, rng: np.random.Generator) -> np.ndarray:
    """Keep round(fraction * N) points chosen at random without replacement (MATLAB pcdownsample 'random')."""
    index = random_indices(points.shape[0], fraction, rng)
    return points if index is None else points[index]


#: Smallest voxel edge accepted, metres (a tenth of a millimetre: far below any sensor's noise).
MIN_VOXEL_M = 1e-4


def voxel_average(cloud: MapCloud, voxel_m: float) -> MapCloud:
    """One point per occupied voxel of edge ``voxel_m``: the mean of its points, intensities and colours.

    The voxels are Open3D's (``voxel_down_sample``): anchored half a voxel below
    the cloud's minimum bound, so the same points fall together; the output is
    ordered by voxel. Colours are averaged per channel and rounded. Raises
    :class:`BagtoolsError` when the points span more voxels per axis than a
    32-bit index holds (Open3D's limit, kept so results agree).
    """
    points = cloud.points
    if points.shape[0] == 0:
        return cloud
    p = points.astype(np.float64)
    lo, hi = p.min(axis=0), p.max(axis=0)
    span_m = float(np.max(hi - lo)) + voxel_m
    if not span_m / voxel_m < np.iinfo(np.int32).max:
        raise BagtoolsError(f"--voxel {voxel_m:g} m is too small for a map spanning {span_m:.4g} m "
                            f"(at most {np.iinfo(np.int32).max} voxels per axis)")
    cells = np.floor((p - (lo - 0.5 * voxel_m)) / voxel_m).astype(np.int64)
    dims = cells.max(axis=0) + 1
    if float(dims[0]) * float(dims[1]) * float(dims[2]) < 2.0**62:
        key = (cells[:, 0] * dims[1] + cells[:, 1]) * dims[2] + cells[:, 2]
        _, voxel, counts = np.unique(key, return_inverse=True, return_counts=True)
    else:  # a sparse map too wide for one int64 key per voxel
        _, voxel, counts = np.unique(cells, axis=0, return_inverse=True, return_counts=True)
    voxel = voxel.reshape(-1)
    n = counts.size

    def mean(values: np.ndarray) -> np.ndarray:
        return np.bincount(voxel, weights=values, minlength=n) / counts

    out = np.column_stack([mean(p[:, k]) for k in range(3)]).astype(np.float32)
    intensity = None if cloud.intensity is None else mean(cloud.intensity.astype(np.float64)).astype(np.float32)
    rgb = None if cloud.rgb is None else np.column_stack(
        [np.rint(mean(cloud.rgb[:, k].astype(np.float64))) for k in range(3)]).astype(np.uint8)
    return MapCloud(out, intensity, rgb)


def voxel_downsample(points: np.ndarray, voxel_m: float) -> np.ndarray:
    """Average the points in each voxel of edge ``voxel_m`` (Open3D's voxel_down_sample); see :func:`voxel_average`."""
    return voxel_average(MapCloud(np.asarray(points, dtype=np.float32)), voxel_m).points


def _concatenate(parts: list[MapCloud]) -> MapCloud:
    intensity = np.concatenate([p.intensity for p in parts]) if all(p.intensity is not None for p in parts) else None
    rgb = np.concatenate([p.rgb for p in parts]) if all(p.rgb is not None for p in parts) else None
    return MapCloud(np.concatenate([p.points for p in parts]), intensity, rgb)


class PointAccumulator:
    """Collects map points (N,3) float32 in the map frame, with their intensity and colour when every input has them.

    With ``voxel_m`` set, the collected points are voxel-averaged whenever the
    pending part grows past ``compact_every`` points, so memory stays bounded by
    the number of occupied voxels. An attribute some input lacks is dropped
    from the whole map (:attr:`dropped` names it).
    """

    def __init__(self, voxel_m: float | None = None, compact_every: int = 2_000_000) -> None:
        self.voxel_m = voxel_m
        self.compact_every = compact_every
        self._parts: list[MapCloud] = []
        self._pending = 0
        self.points_added = 0
        self.dropped: set[str] = set()
        self._present: dict[str, bool] = {}

    def add(self, points_map: np.ndarray, intensity: np.ndarray | None = None, rgb: np.ndarray | None = None) -> None:
        """Add (N,3) points already in the map frame, with (N,) intensities and (N,3) uint8 colours if the sensor gave them."""
        if points_map.shape[0] == 0:
            return
        part = MapCloud(np.asarray(points_map, dtype=np.float32),
                        None if intensity is None else np.asarray(intensity, dtype=np.float32),
                        None if rgb is None else np.asarray(rgb, dtype=np.uint8))
        present = {"intensity": part.intensity is not None, "rgb": part.rgb is not None}
        if self.points_added == 0:
            self._present = present
        self.dropped.update(name for name, has in present.items() if has != self._present[name])
        self._parts.append(part)
        self._pending += part.points.shape[0]
        self.points_added += part.points.shape[0]
        if self.voxel_m and self._pending > self.compact_every:
            self._parts = [voxel_average(self._merged(), self.voxel_m)]
            self._pending = 0

    def _merged(self) -> MapCloud:
        return _concatenate(self._parts)  # an attribute some part lacks is None

    def cloud(self) -> MapCloud:
        """The map (voxel-averaged if ``voxel_m`` is set), with the attributes every input had."""
        if not self._parts:
            return MapCloud(np.empty((0, 3), dtype=np.float32))
        merged = self._merged()
        if self.voxel_m:
            merged = voxel_average(merged, self.voxel_m)
            self._parts, self._pending = [merged], 0
        return merged

    def points(self) -> np.ndarray:
        """The map's points: (M,3) float32 (voxel-averaged if ``voxel_m`` is set)."""
        return self.cloud().points
