"""map-cloud --refine: each cloud registered to the map built so far with Open3D's ICP.

tf places a depth camera's clouds by the robot's odometry, which drifts: walls
seen again a lap later land beside themselves. :class:`CloudRefiner` takes the
clouds in order. Each one starts where tf puts it, corrected as the cloud
before it was (odometry drifts slowly: the correction carries over), and is
registered to the map so far, cut to the cloud's reach, by Open3D's ICP:
point-to-plane, or coloured ICP (Park et al. 2017) when the clouds carry
colour. A registration that matches too little of the cloud (``MIN_FITNESS``)
keeps the starting pose. The cloud then joins the map where the map holds no
point yet (one point per ``voxel_m`` voxel, the first seen), so later clouds,
and the robot's next pass, register to what was seen first.

Open3D is imported here only, when a refinement is asked for (it takes about a
second to load). It runs on one thread: its ICP sums over correspondences on
oneAPI TBB threads, in an order that changes from run to run, and so did the
map's last digits; a refinement gives the same map every time.

Poses are 4x4 homogeneous transforms T_frame_sensor (metres), frame the map's.
"""

from __future__ import annotations

from typing import Any

import numpy as np

#: Voxel edge of the registration clouds and of the map they register to (m).
REFINE_VOXEL_M = 0.05
#: Farthest a point may lie from its match in ICP (m): the drift since the last cloud, plus noise.
MAX_CORRESPONDENCE_M = 0.2
#: A registration that pairs less than this share of the cloud's points keeps tf's (corrected) pose.
MIN_FITNESS = 0.3
#: Too few map points within the cloud's reach to register to (the first clouds, or a place seen for the first time).
MIN_TARGET_POINTS = 200
#: The map's points are indexed by cubes of this edge (m), so that finding those within a cloud's reach reads the
#: cubes around it, not the whole map (which grows with the bag).
BLOCK_M = 1.0


class CloudRefiner:
    """Registers clouds, in order, to the map built from the ones before (see the module docstring).

    The map keeps the first point that fell in each ``voxel_m`` voxel: a later
    pass over a place registers to what the first pass saw there (the least
    drifted), not to its own recent clouds, which carry the drift along. Its
    arrays grow by doubling and its points are indexed by ``BLOCK_M`` cubes:
    a cloud costs what it adds and what lies within its reach, not the map's size.

    Args:
        voxel_m: voxel edge of the registration clouds and of the map (m).
    """

    def __init__(self, voxel_m: float = REFINE_VOXEL_M) -> None:
        import open3d as o3d  # lazily: only a refinement pays for loading Open3D

        o3d.utility.set_max_threads(1)  # TBB's reductions in a fixed order: the same map every run
        self._o3d = o3d
        self.voxel_m = voxel_m
        self._n = 0  # the map: the first _n rows of points, normals and colours (0..1), map frame
        self._points = np.zeros((0, 3))
        self._normals = np.zeros((0, 3))
        self._colors: np.ndarray | None = None
        self._voxels = np.zeros(0, dtype=np.int64)  # sorted keys of the voxels the map holds a point in
        self._blocks: dict[int, list[np.ndarray]] = {}  # BLOCK_M cube key -> row indices of the map's points in it
        self.correction = np.eye(4)  # T_refined_tf of the last cloud: where tf's frame really was
        self.registered = 0  # clouds registered (the others kept the corrected tf pose)
        self.fitness: list[float] = []
        self._estimation = o3d.pipelines.registration
        self._criteria = o3d.pipelines.registration.ICPConvergenceCriteria(max_iteration=30)

    @property
    def points(self) -> np.ndarray:
        """The map's points (M, 3), map frame (m)."""
        return self._points[:self._n]

    @property
    def normals(self) -> np.ndarray:
        """Their unit normals (M, 3), map frame."""
        return self._normals[:self._n]

    @property
    def colors(self) -> np.ndarray | None:
        """Their colours (M, 3) in 0..1, or None when the clouds carry none."""
        return None if self._colors is None else self._colors[:self._n]

    def refine(self, points_sensor: np.ndarray, T_frame_sensor: np.ndarray, rgb: np.ndarray | None = None) -> np.ndarray:
        """The refined T_frame_sensor (4,4) of one cloud ((N,3) points in its sensor frame, m; ``rgb`` (N,3) uint8
        or None), given tf's; the cloud joins the map there."""
        source = self._cloud(points_sensor, rgb)
        initial = self.correction @ T_frame_sensor
        pose = initial
        if len(source.points) >= 3:
            target = self._target(initial, source)
            if target is not None:
                result = self._register(source, target, initial, rgb is not None)
                if result is not None and result.fitness >= MIN_FITNESS:
                    pose = np.asarray(result.transformation, dtype=np.float64)
                    self.registered += 1
                    self.fitness.append(float(result.fitness))
        self.correction = pose @ np.linalg.inv(T_frame_sensor)
        self._add(source, pose)
        return pose

    def _cloud(self, points: np.ndarray, rgb: np.ndarray | None) -> Any:
        o3d = self._o3d
        cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.asarray(points, dtype=np.float64)))
        if rgb is not None:
            cloud.colors = o3d.utility.Vector3dVector(np.asarray(rgb, dtype=np.float64) / 255.0)
        cloud = cloud.voxel_down_sample(self.voxel_m)
        cloud.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=4.0 * self.voxel_m, max_nn=30))
        return cloud

    def _target(self, initial: np.ndarray, source: Any) -> Any | None:
        """The map within the cloud's reach (its bounding box where ``initial`` puts it, plus the ICP distance)."""
        if self._n < MIN_TARGET_POINTS:
            return None
        placed = np.asarray(source.points) @ initial[:3, :3].T + initial[:3, 3]
        margin = MAX_CORRESPONDENCE_M + self.voxel_m
        lo, hi = placed.min(axis=0) - margin, placed.max(axis=0) + margin
        rows = self._rows_near(lo, hi)
        rows = rows[np.all((self._points[rows] >= lo) & (self._points[rows] <= hi), axis=1)]
        if len(rows) < MIN_TARGET_POINTS:
            return None
        o3d = self._o3d
        target = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(self._points[rows]))
        target.normals = o3d.utility.Vector3dVector(self._normals[rows])
        if self._colors is not None:
            target.colors = o3d.utility.Vector3dVector(self._colors[rows])
        return target

    def _rows_near(self, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
        """Row indices (sorted) of the map's points in the BLOCK_M cubes that meet the box ``lo``..``hi`` (m)."""
        first, last = np.floor(lo / BLOCK_M).astype(np.int64), np.floor(hi / BLOCK_M).astype(np.int64)
        if np.prod(last - first + 1, dtype=np.float64) <= len(self._blocks):  # the cubes of the box
            cells = np.stack(np.meshgrid(*(np.arange(a, b + 1) for a, b in zip(first, last)), indexing="ij"), axis=-1)
            keys = _cell_keys(cells.reshape(-1, 3)).tolist()
        else:  # a box larger than the map: the map's cubes that lie in it
            keys = np.fromiter(self._blocks, dtype=np.int64, count=len(self._blocks))
            cells = _key_cells(keys)
            keys = keys[np.all((cells >= first) & (cells <= last), axis=1)].tolist()
        parts = [rows for key in keys for rows in self._blocks.get(key, ())]
        return np.sort(np.concatenate(parts)) if parts else np.zeros(0, dtype=np.int64)

    def _register(self, source: Any, target: Any, initial: np.ndarray, coloured: bool) -> Any | None:
        reg = self._estimation
        if coloured and target.has_colors():
            try:
                return reg.registration_colored_icp(source, target, MAX_CORRESPONDENCE_M, initial,
                                                    reg.TransformationEstimationForColoredICP(), self._criteria)
            except RuntimeError:  # too few colour correspondences: the geometry alone
                pass
        return reg.registration_icp(source, target, MAX_CORRESPONDENCE_M, initial,
                                    reg.TransformationEstimationPointToPlane(), self._criteria)

    def _add(self, source: Any, pose: np.ndarray) -> None:
        """The cloud's points (placed at ``pose``) that fall in voxels the map holds no point in yet."""
        R, t = pose[:3, :3], pose[:3, 3]
        points = np.asarray(source.points) @ R.T + t
        keys = _voxel_keys(points, self.voxel_m)
        keys, first = np.unique(keys, return_index=True)
        where = np.searchsorted(self._voxels, keys)
        new = (where == len(self._voxels)) | (self._voxels[np.minimum(where, len(self._voxels) - 1)] != keys) \
            if len(self._voxels) else np.ones(len(keys), dtype=bool)
        rows = first[new]
        coloured = source.has_colors() and (self._colors is not None or self._n == 0)
        start = self._reserve(len(rows), coloured)
        self._points[start:self._n] = points[rows]
        self._normals[start:self._n] = np.asarray(source.normals)[rows] @ R.T
        if coloured:
            self._colors[start:self._n] = np.asarray(source.colors)[rows]
        else:
            self._colors = None
        self._voxels = np.insert(self._voxels, where[new], keys[new])
        cube = _voxel_keys(points[rows], BLOCK_M)
        order = np.argsort(cube, kind="stable")
        cubes, starts = np.unique(cube[order], return_index=True)
        for key, group in zip(cubes.tolist(), np.split(order + start, starts[1:])):
            self._blocks.setdefault(key, []).append(group)

    def _reserve(self, n: int, coloured: bool) -> int:
        """Room for ``n`` more points (the arrays doubled when full); the first new row."""
        start, self._n = self._n, self._n + n
        if self._n > len(self._points):
            size = max(self._n, 2 * len(self._points), 1024)
            for name in ("_points", "_normals") + (("_colors",) if coloured else ()):
                old = getattr(self, name)
                grown = np.zeros((size, 3))
                if old is not None:
                    grown[:start] = old[:start]
                setattr(self, name, grown)
        elif coloured and self._colors is None:
            self._colors = np.zeros((len(self._points), 3))
        return start


def _voxel_keys(points: np.ndarray, voxel_m: float) -> np.ndarray:
    """One int64 key per (N,3) point: its ``voxel_m`` voxel (21 bits per axis, about 100 km at 5 cm)."""
    return _cell_keys(np.floor(points / voxel_m).astype(np.int64))


def _cell_keys(cells: np.ndarray) -> np.ndarray:
    """One int64 key per (N,3) integer cell (21 bits per axis)."""
    cells = cells + (1 << 20)
    return (cells[:, 0] << 42) | (cells[:, 1] << 21) | cells[:, 2]


def _key_cells(keys: np.ndarray) -> np.ndarray:
    """The (N,3) integer cells of :func:`_cell_keys`' keys."""
    mask = (1 << 21) - 1
    return np.stack((keys >> 42, (keys >> 21) & mask, keys & mask), axis=1) - (1 << 20)
