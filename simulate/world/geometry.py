"""Vectorized 2D/3D geometry kernels used by :mod:`bagtools_simulate.world`.

Every function works on whole arrays: rays x faces, points x edges, as numpy
broadcasts. Callers chunk the ray/point axis so temporaries stay small.
Conventions: distances in metres, angles in radians, ``inf`` where a ray
misses. Edge outward normals are ``(ey, -ex)`` for an edge vector ``e``, which
points out of the solid when outer rings run counter-clockwise and holes
clockwise (see :func:`orient_ring`).
"""

from __future__ import annotations

import numpy as np

#: Largest number of (ray or point) x (face or edge) elements handled at once.
CHUNK_ELEMENTS = 1 << 18


def chunk_size(n_faces: int) -> int:
    """Number of rays or points per chunk for ``n_faces`` faces (at least 256)."""
    return max(256, CHUNK_ELEMENTS // max(1, n_faces))


def ring_signed_area(ring_xy: np.ndarray) -> float:
    """Signed area of a closed ring (N,2) in m^2: positive when counter-clockwise."""
    x, y = ring_xy[:, 0], ring_xy[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def orient_ring(ring_xy: np.ndarray, counter_clockwise: bool) -> np.ndarray:
    """Return ``ring_xy`` (N,2) reordered to run counter-clockwise or clockwise."""
    is_ccw = ring_signed_area(ring_xy) > 0.0
    return ring_xy if is_ccw == counter_clockwise else ring_xy[::-1].copy()


def ring_edges(ring_xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Edges of a closed ring (N,2): start points (N,2) and end points (N,2)."""
    return ring_xy, np.roll(ring_xy, -1, axis=0)


def point_segment_distance(
    points_xy: np.ndarray, p0: np.ndarray, p1: np.ndarray
) -> np.ndarray:
    """Distance (N,E) from each point (N,2) to each segment p0 (E,2) -> p1 (E,2)."""
    e = p1 - p0  # (E,2)
    len2 = np.maximum(np.einsum("ij,ij->i", e, e), 1e-300)
    wx = points_xy[:, 0:1] - p0[None, :, 0]
    wy = points_xy[:, 1:2] - p0[None, :, 1]
    s = np.clip((wx * e[:, 0] + wy * e[:, 1]) / len2, 0.0, 1.0)
    dx = wx - s * e[:, 0]
    dy = wy - s * e[:, 1]
    return np.sqrt(dx * dx + dy * dy)


def crossings(points_xy: np.ndarray, p0: np.ndarray, p1: np.ndarray) -> np.ndarray:
    """Even-odd crossing matrix (N,E) bool: a +x ray from each point crosses each edge.

    Summing a row over the edges of one solid (all its rings) and taking the
    parity tells whether the point is inside that solid.
    """
    y = points_xy[:, 1:2]
    x = points_xy[:, 0:1]
    y0, y1 = p0[None, :, 1], p1[None, :, 1]
    straddles = (y0 > y) != (y1 > y)
    dy = np.where(p1[:, 1] == p0[:, 1], 1.0, p1[:, 1] - p0[:, 1])
    x_cross = p0[None, :, 0] + (y - y0) * ((p1[:, 0] - p0[:, 0]) / dy)
    return straddles & (x < x_cross)


def ray_vertical_faces(
    origin: np.ndarray,
    dirs: np.ndarray,
    p0: np.ndarray,
    p1: np.ndarray,
    zmin: np.ndarray | None,
    zmax: np.ndarray | None,
) -> np.ndarray:
    """Nearest hit of rays with vertical faces that face the origin, inf where none.

    Args:
        origin: ray origin (2,) or (3,) in m; z is used only with z limits.
        dirs: ray directions (K,2) or (K,3); the returned t is in units of |dir|.
        p0, p1: face bottom edges (F,2), oriented so the outward normal
            (ey, -ex) points towards the origin (back faces must be culled
            by the caller).
        zmin, zmax: face z limits (F,) in m, or None for a 2D (planar) cast.

    Returns:
        (K,) parameter t >= 0 of the first face entered, ``inf`` if none.
    """
    k = dirs.shape[0]
    if p0.shape[0] == 0:
        return np.full(k, np.inf)
    ex = (p1[:, 0] - p0[:, 0])[:, None]
    ey = (p1[:, 1] - p0[:, 1])[:, None]
    wx = (p0[:, 0] - origin[0])[:, None]
    wy = (p0[:, 1] - origin[1])[:, None]
    w_cross_e = wx * ey - wy * ex  # (F,1), < 0 for faces towards the origin
    dx = dirs[:, 0]
    dy = dirs[:, 1]
    denom = dx * ey - dy * ex  # (F,K); < 0 when the ray enters the face
    s_num = wx * dy - wy * dx  # s = s_num / denom must lie in [0, 1]
    hit = (denom < 0.0) & (s_num <= 0.0) & (s_num >= denom)
    with np.errstate(divide="ignore", invalid="ignore"):  # misses are masked by `hit`
        t = w_cross_e / denom
        if zmin is not None and zmax is not None:
            dz_hit = t * dirs[:, 2]
            hit &= (dz_hit >= (zmin - origin[2])[:, None]) & (dz_hit <= (zmax - origin[2])[:, None])
    return np.where(hit, t, np.inf).min(axis=0)


def ray_cylinder_sides(
    origin: np.ndarray,
    dirs: np.ndarray,
    centers: np.ndarray,
    radii: np.ndarray,
    zmin: np.ndarray | None,
    zmax: np.ndarray | None,
) -> np.ndarray:
    """Nearest entering hit of rays with the sides of vertical cylinders, inf where none.

    Args:
        origin: (2,) or (3,) ray origin in m, outside every given cylinder in xy.
        dirs: (K,2) or (K,3) directions; t is in units of |dir|.
        centers: (C,2) axis positions in m; radii: (C,) in m.
        zmin, zmax: (C,) z limits in m, or None for a planar cast.

    Returns:
        (K,) first-hit parameter t, ``inf`` where no cylinder side is hit.
    """
    k = dirs.shape[0]
    if centers.shape[0] == 0:
        return np.full(k, np.inf)
    wx = (origin[0] - centers[:, 0])[:, None]
    wy = (origin[1] - centers[:, 1])[:, None]
    c = wx * wx + wy * wy - (radii * radii)[:, None]  # (C,1) > 0 outside
    dx = dirs[:, 0]
    dy = dirs[:, 1]
    a = dx * dx + dy * dy  # (K,)
    b = dx * wx + dy * wy  # (C,K)
    disc = b * b - a * c
    ok = (disc >= 0.0) & (b < 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):  # misses are masked by `ok`
        t = (-b - np.sqrt(disc)) / a
        if zmin is not None and zmax is not None:
            dz_hit = t * dirs[:, 2]
            ok &= (dz_hit >= (zmin - origin[2])[:, None]) & (dz_hit <= (zmax - origin[2])[:, None])
    return np.where(ok, t, np.inf).min(axis=0)


def wrap_angle(a: np.ndarray) -> np.ndarray:
    """Angles wrapped to [-pi, pi)."""
    return (a + np.pi) % (2.0 * np.pi) - np.pi


def _relative_bearing(x: np.ndarray, y: np.ndarray, c: float, s: float) -> np.ndarray:
    """Bearings in [-pi, pi] of vectors (x, y) relative to the unit direction (c, s): wrap(atan2(y, x) - atan2(s, c))."""
    return np.arctan2(c * y - s * x, c * x + s * y)


def angular_bins(
    origin_xy: np.ndarray,
    dirs_xy: np.ndarray,
    seg_p0: np.ndarray,
    seg_p1: np.ndarray,
    centers: np.ndarray,
    radii: np.ndarray,
    n_bins: int,
) -> tuple[np.ndarray, list[tuple[slice, np.ndarray, np.ndarray]]]:
    """Group rays by bearing and list the side faces each group can see.

    A face (segment p0 -> p1, or a circle) is kept for a group when the bearing
    interval it subtends from the origin overlaps the group's bearing interval;
    rays in a group can hit no other face. The origin must be outside every
    circle and off every segment. With one group every face is kept (no
    bearings are computed).

    Args:
        origin_xy: (2,) ray origin in m.
        dirs_xy: (K,2) horizontal parts of the ray directions.
        seg_p0, seg_p1: (F,2) segments; centers (C,2), radii (C,) circles.
        n_bins: number of bearing groups (>= 1).

    Returns:
        The indices of the rays that have a horizontal component, ordered by
        group (the others cannot hit a vertical face and are left out), and one
        (slice of that order, segment indices, circle indices) per non-empty group.
    """
    h2 = dirs_xy[:, 0] ** 2 + dirs_xy[:, 1] ** 2
    moving = h2 > 1e-24
    every = bool(moving.all())
    rays = np.arange(len(dirs_xy)) if every else np.flatnonzero(moving)
    if len(rays) == 0:
        return rays, []
    n_bins = max(1, int(n_bins))
    if n_bins == 1:
        return rays, [(slice(0, len(rays)), np.arange(len(seg_p0)), np.arange(len(centers)))]
    d = dirs_xy if every else dirs_xy[rays]
    mean = d.sum(axis=0)
    norm = float(np.hypot(*mean))
    # Bearings are taken relative to the rays' mean direction (c, s), so that a fan of rays does not straddle +-pi.
    c, s = (float(mean[0]) / norm, float(mean[1]) / norm) if norm > 1e-12 else (1.0, 0.0)
    rel = _relative_bearing(d[:, 0], d[:, 1], c, s)
    lo, hi = float(rel.min()), float(rel.max())
    width = max(hi - lo, 1e-9) / n_bins
    bin_id = np.minimum(((rel - lo) / width).astype(np.intp), n_bins - 1)
    b0 = lo + width * np.arange(n_bins) - 1e-9
    b1 = b0 + width + 2e-9

    ox, oy = origin_xy[0], origin_xy[1]
    r0 = _relative_bearing(seg_p0[:, 0] - ox, seg_p0[:, 1] - oy, c, s)
    r1 = _relative_bearing(seg_p1[:, 0] - ox, seg_p1[:, 1] - oy, c, s)
    span = wrap_angle(r1 - r0)
    seg_start = r0 + np.minimum(span, 0.0)
    seg_end = seg_start + np.abs(span)
    rc = np.hypot(centers[:, 0] - ox, centers[:, 1] - oy)
    ac = _relative_bearing(centers[:, 0] - ox, centers[:, 1] - oy, c, s)
    half = np.arcsin(np.clip(radii / np.maximum(rc, 1e-12), 0.0, 1.0))
    starts = np.concatenate([seg_start, ac - half])[:, None]
    ends = np.concatenate([seg_end, ac + half])[:, None]
    overlap = np.zeros((len(starts), n_bins), dtype=bool)
    for shift in (-2.0 * np.pi, 0.0, 2.0 * np.pi):
        overlap |= (starts <= b1 + shift) & (ends >= b0 + shift)

    order = rays[np.argsort(bin_id.astype(np.int16), kind="stable")]  # radix sort
    bounds = np.concatenate(([0], np.cumsum(np.bincount(bin_id, minlength=n_bins)))).tolist()
    n_seg = len(seg_p0)
    groups = []
    for b in range(n_bins):
        if bounds[b + 1] > bounds[b]:
            faces = overlap[:, b]
            groups.append((slice(bounds[b], bounds[b + 1]), np.flatnonzero(faces[:n_seg]), np.flatnonzero(faces[n_seg:])))
    return order, groups
