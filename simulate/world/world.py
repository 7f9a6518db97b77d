"""Worlds for the simulator: solid prisms and cylinders on a floor, with fast ray casts.

A world is a JSON object (metres, radians, z up, x/y in the map frame). Two
forms are read, and may be mixed in one file:

The TurtleBot3 form (``simulate/data/turtlebot3_world.json``)::

    {"name": "turtlebot3_world",
     "shell_wall": {"inner": [[x, y], ...], "outer": [[x, y], ...], "z": [zmin, zmax]},
     "hexagon_obstacles": [{"name": "head", "vertices": [[x, y], ...], "z": [zmin, zmax]}, ...],
     "cylinders": [{"center": [x, y], "radius": r, "z": [zmin, zmax]}, ...],
     "spawn": {"x": -2.0, "y": -0.5, "yaw": 0.0}}

The shell wall is the solid band between ``outer`` and ``inner``; free space is
inside ``inner`` (it becomes the world's boundary).

The general form, for your own worlds::

    {"name": "my_lab",
     "polygons": [{"name": "desk", "vertices": [[x, y], ...], "holes": [[[x, y], ...]],
                   "z": [zmin, zmax]}, ...],
     "cylinders": [{"name": "bin", "center": [x, y], "radius": r, "z": [zmin, zmax]}, ...],
     "boundary": [[x, y], ...],
     "spawn": {"x": 0.0, "y": 0.0, "yaw": 0.0}}

Each polygon is a solid vertical prism between ``z[0]`` and ``z[1]``: its outline
is ``vertices`` (at least 3, any orientation, convex or not) minus optional
``holes``. Cylinders are solid with flat caps. ``boundary`` (optional) is the
outline of the free space: points outside it have negative clearance. The
floor is the plane z = 0. ``name`` defaults to the file name; ``spawn``
defaults to the origin and must lie in free space. Other keys (``units``,
``provenance``, ``note``, a hexagon's ``center``) are kept but not used.
"""

from __future__ import annotations

import copy
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from bagtools.errors import BagtoolsError
from bagtools_simulate.world import geometry as geo

#: Rays per bearing group in ray casts: fewer groups mean less Python overhead,
#: more groups mean fewer faces per ray.
RAYS_PER_BEARING_GROUP = 2400

#: Folder of the packaged worlds (``<name>.json``).
DATA_DIR = Path(__file__).resolve().parent.parent / "data"


def packaged_world_names() -> list[str]:
    """Names of the worlds shipped in ``simulate/data`` (sorted)."""
    return sorted(p.stem for p in DATA_DIR.glob("*.json"))


@dataclass(frozen=True)
class Prism:
    """A solid vertical prism: outline rings (outer CCW, holes CW) in m, z range in m."""

    name: str
    rings: tuple[np.ndarray, ...]
    zmin: float
    zmax: float


@dataclass(frozen=True)
class Cylinder:
    """A solid vertical cylinder: axis at ``center_xy`` (m), ``radius_m``, z range in m."""

    name: str
    center_xy: tuple[float, float]
    radius_m: float
    zmin: float
    zmax: float


class World:
    """Static world geometry with vectorized ray casts and distance queries.

    Build one with :func:`load_world` or :meth:`World.from_dict`. All inputs and
    outputs are in metres in the map frame; the floor is the plane z = 0.
    """

    def __init__(
        self,
        name: str,
        prisms: list[Prism],
        cylinders: list[Cylinder],
        boundary_xy: np.ndarray | None,
        spawn_xy_yaw: tuple[float, float, float],
        source: dict[str, Any],
    ) -> None:
        self.name = name
        self.prisms = tuple(prisms)
        self.cylinders = tuple(cylinders)
        self.boundary_xy = boundary_xy
        self.spawn_xy_yaw = spawn_xy_yaw
        self._source = copy.deepcopy(source)

        p0s, p1s, owner = [], [], []
        for i, prism in enumerate(self.prisms):
            for ring in prism.rings:
                a, b = geo.ring_edges(ring)
                p0s.append(a)
                p1s.append(b)
                owner.append(np.full(len(ring), i))
        self._p0 = np.concatenate(p0s) if p0s else np.zeros((0, 2))
        self._p1 = np.concatenate(p1s) if p1s else np.zeros((0, 2))
        self._edge_prism = np.concatenate(owner) if owner else np.zeros(0, dtype=int)
        zmin = np.array([p.zmin for p in self.prisms])
        zmax = np.array([p.zmax for p in self.prisms])
        self._prism_zmin = zmin
        self._prism_zmax = zmax
        self._edge_zmin = zmin[self._edge_prism] if len(zmin) else np.zeros(0)
        self._edge_zmax = zmax[self._edge_prism] if len(zmax) else np.zeros(0)
        e = self._p1 - self._p0
        self._edge_normal = np.stack([e[:, 1], -e[:, 0]], axis=1)  # outward, unnormalized

        self._cyl_c = np.array([c.center_xy for c in self.cylinders], dtype=float).reshape(-1, 2)
        self._cyl_r = np.array([c.radius_m for c in self.cylinders], dtype=float)
        self._cyl_zmin = np.array([c.zmin for c in self.cylinders], dtype=float)
        self._cyl_zmax = np.array([c.zmax for c in self.cylinders], dtype=float)

        if boundary_xy is not None:
            self._bnd_p0, self._bnd_p1 = geo.ring_edges(boundary_xy)

    # ------------------------------------------------------------------ building

    @classmethod
    def from_dict(cls, data: Any, path: str | Path | None = None) -> World:
        """Build a world from a parsed JSON object (see the module docstring).

        Raises:
            BagtoolsError: naming ``path`` and the first malformed entry.
        """
        return _parse_world(data, path)

    def to_json(self) -> dict[str, Any]:
        """The world as a JSON-able dict, in the same form it was read from."""
        return copy.deepcopy(self._source)

    @property
    def bounds_xy(self) -> tuple[float, float, float, float]:
        """(xmin, ymin, xmax, ymax) in m of the boundary, or of all geometry without one."""
        if self.boundary_xy is not None:
            pts = self.boundary_xy
        else:
            parts = [self._p0]
            if len(self._cyl_r):
                parts.append(self._cyl_c - self._cyl_r[:, None])
                parts.append(self._cyl_c + self._cyl_r[:, None])
            pts = np.concatenate(parts)
        lo = pts.min(axis=0)
        hi = pts.max(axis=0)
        return float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])

    # ------------------------------------------------------------------ distances

    def clearance_m(
        self, xy: np.ndarray, z_range_m: tuple[float, float] = (0.0, 0.3)
    ) -> np.ndarray:
        """Signed 2D clearance (N,) in m of points ``xy`` (N,2) in the map frame.

        Distance to the nearest outline of any solid whose z range overlaps
        ``z_range_m`` (the robot's height band); negative inside such a solid or
        outside the world's boundary.
        """
        pts = _as_points(xy, 2, "xy")
        z0, z1 = z_range_m
        prism_sel = (self._prism_zmin < z1) & (self._prism_zmax > z0)
        cyl_sel = (self._cyl_zmin < z1) & (self._cyl_zmax > z0)
        edge_sel = prism_sel[self._edge_prism] if len(self._edge_prism) else np.zeros(0, bool)
        p0, p1 = self._p0[edge_sel], self._p1[edge_sel]
        counts = np.bincount(self._edge_prism[edge_sel], minlength=len(self.prisms))[prism_sel]
        starts = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.intp)
        centers, radii = self._cyl_c[cyl_sel], self._cyl_r[cyl_sel]

        out = np.empty(len(pts))
        n_faces = len(p0) + len(radii) + (0 if self.boundary_xy is None else len(self.boundary_xy))
        step = geo.chunk_size(n_faces)
        for i in range(0, len(pts), step):
            q = pts[i : i + step]
            best = np.full(len(q), np.inf)
            if len(p0):
                dist = geo.point_segment_distance(q, p0, p1)
                per_prism = np.minimum.reduceat(dist, starts, axis=1)
                cross = geo.crossings(q, p0, p1).astype(np.int32)
                inside = (np.add.reduceat(cross, starts, axis=1) % 2).astype(bool)
                best = np.min(np.where(inside, -per_prism, per_prism), axis=1)
            if len(radii):
                rho = np.hypot(q[:, 0:1] - centers[:, 0], q[:, 1:2] - centers[:, 1])
                best = np.minimum(best, np.min(rho - radii, axis=1))
            if self.boundary_xy is not None:
                d_b = geo.point_segment_distance(q, self._bnd_p0, self._bnd_p1).min(axis=1)
                inside_b = geo.crossings(q, self._bnd_p0, self._bnd_p1).sum(axis=1) % 2 == 1
                best = np.minimum(best, np.where(inside_b, d_b, -d_b))
            out[i : i + step] = best
        return out

    def surface_distance_2d_m(self, points_xy: np.ndarray, z_m: float | None = None) -> np.ndarray:
        """Distance (N,) in m from points (N,2) to the nearest solid outline in 2D.

        With ``z_m`` only solids whose z range contains that height count
        (e.g. the scanner height, to score an occupancy grid built from scans).
        """
        pts = _as_points(points_xy, 2, "points_xy")
        edge_sel = np.ones(len(self._p0), bool)
        cyl_sel = np.ones(len(self._cyl_r), bool)
        if z_m is not None:
            edge_sel = (self._edge_zmin <= z_m) & (self._edge_zmax >= z_m)
            cyl_sel = (self._cyl_zmin <= z_m) & (self._cyl_zmax >= z_m)
        p0, p1 = self._p0[edge_sel], self._p1[edge_sel]
        centers, radii = self._cyl_c[cyl_sel], self._cyl_r[cyl_sel]
        out = np.empty(len(pts))
        step = geo.chunk_size(len(p0) + len(radii))
        for i in range(0, len(pts), step):
            q = pts[i : i + step]
            best = np.full(len(q), np.inf)
            if len(p0):
                best = geo.point_segment_distance(q, p0, p1).min(axis=1)
            if len(radii):
                rho = np.hypot(q[:, 0:1] - centers[:, 0], q[:, 1:2] - centers[:, 1])
                best = np.minimum(best, np.abs(rho - radii).min(axis=1))
            out[i : i + step] = best
        return out

    def surface_distance_m(self, points_xyz: np.ndarray) -> np.ndarray:
        """Euclidean distance (N,) in m from 3D points (N,3) to the nearest world surface.

        Surfaces are the prisms' side faces and caps, the cylinders' sides and
        caps, and the floor z = 0.
        """
        pts = _as_points(points_xyz, 3, "points_xyz")
        n_prisms = len(self.prisms)
        counts = np.bincount(self._edge_prism, minlength=n_prisms)
        starts = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.intp)
        out = np.empty(len(pts))
        step = geo.chunk_size(2 * len(self._p0) + len(self._cyl_r))
        for i in range(0, len(pts), step):
            q = pts[i : i + step]
            z = q[:, 2:3]
            best = np.abs(q[:, 2])  # the floor
            if len(self._p0):
                d_h = geo.point_segment_distance(q[:, :2], self._p0, self._p1)
                dz = np.maximum(np.maximum(self._edge_zmin - z, z - self._edge_zmax), 0.0)
                best = np.minimum(best, np.sqrt(d_h * d_h + dz * dz).min(axis=1))
                cross = geo.crossings(q[:, :2], self._p0, self._p1).astype(np.int32)
                inside = (np.add.reduceat(cross, starts, axis=1) % 2).astype(bool)
                cap = np.minimum(np.abs(z - self._prism_zmax), np.abs(z - self._prism_zmin))
                best = np.minimum(best, np.where(inside, cap, np.inf).min(axis=1))
            if len(self._cyl_r):
                rho = np.hypot(q[:, 0:1] - self._cyl_c[:, 0], q[:, 1:2] - self._cyl_c[:, 1])
                dz = np.maximum(np.maximum(self._cyl_zmin - z, z - self._cyl_zmax), 0.0)
                side = np.hypot(rho - self._cyl_r, dz)
                cap = np.minimum(np.abs(z - self._cyl_zmax), np.abs(z - self._cyl_zmin))
                cap = np.where(rho <= self._cyl_r, cap, np.inf)
                best = np.minimum(best, np.minimum(side, cap).min(axis=1))
            out[i : i + step] = best
        return out

    # ------------------------------------------------------------------ ray casts

    def raycast_2d(
        self, origin_xy: np.ndarray, angles_rad: np.ndarray, z_m: float, max_range_m: float
    ) -> np.ndarray:
        """Planar ray cast at height ``z_m`` from ``origin_xy`` (2,) in the map frame.

        Only solids whose z range contains ``z_m`` are seen; the floor is not.
        ``angles_rad`` (M,) are map-frame bearings. Returns (M,) float64
        distances in m, ``inf`` where nothing is hit within ``max_range_m``.
        The origin is assumed to be in free space.
        """
        o = _as_vector(origin_xy, 2, "origin_xy")
        ang = np.asarray(angles_rad, dtype=float).reshape(-1)
        dirs = np.stack([np.cos(ang), np.sin(ang)], axis=1)
        edge_ok = (self._edge_zmin <= z_m) & (self._edge_zmax >= z_m)
        cyl_ok = (self._cyl_zmin <= z_m) & (self._cyl_zmax >= z_m)
        out = self._side_hits(o, dirs, max_range_m, edge_ok, cyl_ok, with_z=False)
        out[out > max_range_m] = np.inf
        return out

    def raycast_3d(
        self, origin_xyz: np.ndarray, directions: np.ndarray, max_range_m: float
    ) -> np.ndarray:
        """3D ray cast from ``origin_xyz`` (3,) along ``directions`` (K,3), map frame.

        Hits prism side faces and caps (both faces of the shell band),
        cylinder sides and caps, and the floor z = 0. Directions should be unit
        vectors; the result is the distance along each ray in units of its
        direction's length (metres for unit vectors), ``inf`` where nothing is
        hit within ``max_range_m``. The origin is assumed to be in free space.
        """
        o = _as_vector(origin_xyz, 3, "origin_xyz")
        dirs = np.asarray(directions, dtype=float)
        if dirs.ndim != 2 or dirs.shape[1] != 3:
            raise ValueError(f"directions must have shape (K, 3), got {dirs.shape}")
        t = self._side_hits(
            o, dirs, max_range_m, np.ones(len(self._p0), bool), np.ones(len(self._cyl_r), bool), True
        )
        dz = dirs[:, 2]
        if o[2] > 0.0:  # the floor
            down = dz < 0.0
            t = np.minimum(t, np.where(down, -o[2] / np.where(down, dz, -1.0), np.inf))
        # Caps that face the origin: tops below it, bottoms above it.
        for index, prism in enumerate(self.prisms):
            if o[2] > prism.zmax:
                t = np.minimum(t, self._cap_hits(o, dirs, index, prism.zmax))
            elif o[2] < prism.zmin:
                t = np.minimum(t, self._cap_hits(o, dirs, index, prism.zmin))
        cap_sel = (o[2] > self._cyl_zmax) | (o[2] < self._cyl_zmin)
        if cap_sel.any():
            cap_z = np.where(o[2] > self._cyl_zmax, self._cyl_zmax, self._cyl_zmin)[cap_sel]
            t = np.minimum(
                t, _cylinder_cap_hits(o, dirs, self._cyl_c[cap_sel], self._cyl_r[cap_sel], cap_z)
            )
        t[t > max_range_m] = np.inf
        return t

    def _side_hits(
        self,
        o: np.ndarray,
        dirs: np.ndarray,
        max_range_m: float,
        edge_ok: np.ndarray,
        cyl_ok: np.ndarray,
        with_z: bool,
    ) -> np.ndarray:
        """First hits (K,) of rays with prism side faces and cylinder sides, inf if none.

        Culls faces that point away from the origin, lie beyond ``max_range_m``
        or are outside a group of rays' bearings, so each ray is tested against
        a handful of faces.
        """
        rel = o[:2] - self._p0
        front = np.einsum("ij,ij->i", rel, self._edge_normal) > 0.0
        sel = edge_ok & front
        if sel.any():
            near = geo.point_segment_distance(o[None, :2], self._p0[sel], self._p1[sel])[0]
            sel[np.flatnonzero(sel)[near > max_range_m]] = False
        p0, p1 = self._p0[sel], self._p1[sel]
        ez0, ez1 = (self._edge_zmin[sel], self._edge_zmax[sel]) if with_z else (None, None)
        c_rel = o[:2] - self._cyl_c
        rc = np.sqrt(np.einsum("ij,ij->i", c_rel, c_rel))
        csel = cyl_ok & (rc > self._cyl_r) & (rc - self._cyl_r <= max_range_m)
        centers, radii = self._cyl_c[csel], self._cyl_r[csel]
        cz0, cz1 = (self._cyl_zmin[csel], self._cyl_zmax[csel]) if with_z else (None, None)

        t_out = np.full(len(dirs), np.inf)
        if len(p0) + len(radii) == 0:
            return t_out
        n_bins = min(64, max(1, len(dirs) // RAYS_PER_BEARING_GROUP))
        order, groups = geo.angular_bins(o[:2], dirs[:, :2], p0, p1, centers, radii, n_bins)
        # One gather and one scatter: each group is a contiguous run of the rays sorted by group.
        ordered = np.take(dirs, order, axis=0)
        t_ordered = np.full(len(order), np.inf)
        for run, fsel, csel_g in groups:
            n_faces = len(fsel) + len(csel_g)
            if n_faces == 0:
                continue
            g_p0, g_p1, g_c, g_r = p0[fsel], p1[fsel], centers[csel_g], radii[csel_g]
            g_ez = (None, None) if ez0 is None else (ez0[fsel], ez1[fsel])
            g_cz = (None, None) if cz0 is None else (cz0[csel_g], cz1[csel_g])
            step = geo.chunk_size(n_faces)
            for i in range(run.start, run.stop, step):
                chunk = slice(i, min(i + step, run.stop))
                d = ordered[chunk]
                t = geo.ray_vertical_faces(o, d, g_p0, g_p1, *g_ez)
                if len(g_r):
                    t = np.minimum(t, geo.ray_cylinder_sides(o, d, g_c, g_r, *g_cz))
                t_ordered[chunk] = t
        t_out[order] = t_ordered
        return t_out

    def _ring_edges_of(self, prism_index: int) -> tuple[np.ndarray, np.ndarray]:
        sel = self._edge_prism == prism_index
        return self._p0[sel], self._p1[sel]

    def _cap_hits(self, o: np.ndarray, d: np.ndarray, prism_index: int, z_cap: float) -> np.ndarray:
        """Ray parameter (K,) of hits with one prism's horizontal cap at ``z_cap``."""
        dz = d[:, 2]
        toward = (z_cap - o[2]) * dz > 0.0
        t = np.where(toward, (z_cap - o[2]) / np.where(toward, dz, 1.0), np.inf)
        hit_xy = o[:2] + np.where(np.isfinite(t), t, 0.0)[:, None] * d[:, :2]
        p0, p1 = self._ring_edges_of(prism_index)
        inside = geo.crossings(hit_xy, p0, p1).sum(axis=1) % 2 == 1
        return np.where(toward & inside, t, np.inf)


def _cylinder_cap_hits(
    o: np.ndarray, d: np.ndarray, centers: np.ndarray, radii: np.ndarray, z_caps: np.ndarray
) -> np.ndarray:
    """Ray parameter (K,) of the nearest hit with cylinder caps (disks at ``z_caps``)."""
    dz = d[:, 2:3]
    dzc = z_caps - o[2]  # (C,)
    toward = dzc * dz > 0.0
    t = np.where(toward, dzc / np.where(toward, dz, 1.0), np.inf)
    tt = np.where(np.isfinite(t), t, 0.0)
    hx = o[0] + tt * d[:, 0:1] - centers[:, 0]
    hy = o[1] + tt * d[:, 1:2] - centers[:, 1]
    inside = hx * hx + hy * hy <= radii * radii
    return np.where(toward & inside, t, np.inf).min(axis=1)


def _as_points(a: np.ndarray, dim: int, what: str) -> np.ndarray:
    arr = np.asarray(a, dtype=float)
    if arr.ndim == 1 and arr.shape[0] == dim:
        arr = arr[None, :]
    if arr.ndim != 2 or arr.shape[1] != dim:
        raise ValueError(f"{what} must have shape (N, {dim}), got {np.shape(a)}")
    return arr


def _as_vector(a: np.ndarray, dim: int, what: str) -> np.ndarray:
    arr = np.asarray(a, dtype=float).reshape(-1)
    if arr.shape != (dim,):
        raise ValueError(f"{what} must have {dim} elements, got shape {np.shape(a)}")
    return arr


# ---------------------------------------------------------------------- parsing


def load_world(name_or_path: str | Path) -> World:
    """Load a packaged world by name (e.g. ``"turtlebot3_world"``) or a world JSON file.

    Raises:
        BagtoolsError: the file is missing or unreadable, is not JSON, or is not
            a valid world; the message names the file and the problem.
    """
    text = str(name_or_path)
    packaged = DATA_DIR / f"{text}.json"
    is_plain_name = "/" not in text and "\\" not in text and not text.endswith(".json")
    path = packaged if is_plain_name and packaged.is_file() else Path(name_or_path)
    if path.is_dir():
        raise BagtoolsError("is a directory, not a world JSON file", path)
    if not path.is_file():
        names = ", ".join(packaged_world_names())
        raise BagtoolsError(
            f"no such world file or packaged world (packaged worlds: {names})", path
        )
    try:
        raw = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise BagtoolsError(f"cannot read world file: {exc}", path) from None
    try:
        data = json.loads(raw)
    except json.JSONDecodeError as exc:
        raise BagtoolsError(
            f"not valid JSON: {exc.msg} at line {exc.lineno} column {exc.colno}", path
        ) from None
    if isinstance(data, dict) and "name" not in data:
        data = {"name": path.stem, **data}
    return World.from_dict(data, path)


def _parse_world(data: Any, path: str | Path | None) -> World:
    def fail(problem: str) -> BagtoolsError:
        return BagtoolsError(f"bad world: {problem}", path)

    if not isinstance(data, dict):
        raise fail("the file must hold a JSON object")
    name = data.get("name", "world")
    if not isinstance(name, str) or not name:
        raise fail("'name' must be a non-empty string")

    prisms: list[Prism] = []
    cylinders: list[Cylinder] = []
    boundary: np.ndarray | None = None

    if "shell_wall" in data:
        wall = data["shell_wall"]
        if not isinstance(wall, dict):
            raise fail("'shell_wall' must be an object with 'inner', 'outer' and 'z'")
        inner = _ring(wall.get("inner"), "shell_wall.inner", fail)
        outer = _ring(wall.get("outer"), "shell_wall.outer", fail)
        z0, z1 = _z_range(wall.get("z"), "shell_wall.z", fail)
        prisms.append(
            Prism(
                "shell_wall",
                (geo.orient_ring(outer, True), geo.orient_ring(inner, False)),
                z0,
                z1,
            )
        )
        boundary = inner

    for key in ("hexagon_obstacles", "polygons"):
        items = data.get(key, [])
        if not isinstance(items, list):
            raise fail(f"'{key}' must be a list")
        for i, item in enumerate(items):
            where = f"{key}[{i}]"
            if not isinstance(item, dict):
                raise fail(f"{where} must be an object with 'vertices' and 'z'")
            outer = _ring(item.get("vertices"), f"{where}.vertices", fail)
            holes_raw = item.get("holes", [])
            if not isinstance(holes_raw, list):
                raise fail(f"{where}.holes must be a list of rings")
            holes = [_ring(h, f"{where}.holes[{j}]", fail) for j, h in enumerate(holes_raw)]
            z0, z1 = _z_range(item.get("z"), f"{where}.z", fail)
            label = item.get("name", where)
            rings = (geo.orient_ring(outer, True),) + tuple(geo.orient_ring(h, False) for h in holes)
            prisms.append(Prism(str(label), rings, z0, z1))

    items = data.get("cylinders", [])
    if not isinstance(items, list):
        raise fail("'cylinders' must be a list")
    for i, item in enumerate(items):
        where = f"cylinders[{i}]"
        if not isinstance(item, dict):
            raise fail(f"{where} must be an object with 'center', 'radius' and 'z'")
        center = _numbers(item.get("center"), 2, f"{where}.center", fail)
        radius = item.get("radius")
        if not _is_number(radius) or not radius > 0:
            raise fail(f"{where}.radius must be a positive number of metres")
        z0, z1 = _z_range(item.get("z"), f"{where}.z", fail)
        cylinders.append(
            Cylinder(str(item.get("name", where)), (center[0], center[1]), float(radius), z0, z1)
        )

    if "boundary" in data:
        boundary = _ring(data["boundary"], "boundary", fail)
    if not prisms and not cylinders:
        raise fail("no obstacles: give 'polygons', 'cylinders' or 'shell_wall'")

    spawn = data.get("spawn", {"x": 0.0, "y": 0.0, "yaw": 0.0})
    if not isinstance(spawn, dict):
        raise fail("'spawn' must be an object with 'x', 'y' and optional 'yaw'")
    sx, sy, syaw = spawn.get("x"), spawn.get("y"), spawn.get("yaw", 0.0)
    if not all(_is_number(v) for v in (sx, sy, syaw)):
        raise fail("'spawn' needs numeric 'x', 'y' (and 'yaw' in radians)")

    world = World(
        name, prisms, cylinders, boundary, (float(sx), float(sy), float(syaw)), data
    )
    if world.clearance_m(np.array([[sx, sy]]))[0] <= 0.0:
        raise fail(f"spawn point ({sx}, {sy}) is not in free space")
    return world


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def _numbers(v: Any, n: int, where: str, fail: Any) -> list[float]:
    if not isinstance(v, list) or len(v) != n or not all(_is_number(x) for x in v):
        raise fail(f"{where} must be a list of {n} numbers")
    return [float(x) for x in v]


def _z_range(v: Any, where: str, fail: Any) -> tuple[float, float]:
    z0, z1 = _numbers(v, 2, where, fail)
    if not z0 < z1:
        raise fail(f"{where} must be [zmin, zmax] with zmin < zmax")
    return z0, z1


def _ring(v: Any, where: str, fail: Any) -> np.ndarray:
    if not isinstance(v, list) or len(v) < 3:
        raise fail(f"{where} must be a list of at least 3 [x, y] points")
    pts = np.array([_numbers(p, 2, f"{where}[{i}]", fail) for i, p in enumerate(v)])
    if abs(geo.ring_signed_area(pts)) < 1e-12:
        raise fail(f"{where} encloses no area")
    return pts
