"""Loop-closure search: which older keyframes a new keyframe may see again, the match, and the checks.

For each new keyframe ``b`` (:meth:`LoopClosureSearch.candidates`):

1. **Reach.** The back end gives, for every node, the graph distance ``D(a)`` to
   ``b`` (metres of odometry along the shortest path through the graph; a loop
   edge counts ``loop_edge_m``): the relative pose of ``a`` and ``b`` is known
   to about ``sigma_t = drift_per_m * D`` metres and ``sigma_r =
   drift_rad_per_m * D`` radians. Older keyframes at least ``min_travel_m``
   behind ``b`` along the path (and far enough back in the chain that the two
   local maps below share no keyframe: else the match only repeats the front
   end's own chain) whose estimated position lies within ``search_radius_m +
   gate_sigmas * sigma_t`` of ``b``'s are candidates.
   Candidates are grouped into runs of consecutive keyframes (one pass of the
   robot through the place); the nearest keyframe of each run is tried, the
   ``max_candidates`` nearest runs at most, and a run already tied to ``b`` by
   a loop accepted within the last ``loop_spacing_m`` of path is skipped.
2. **Match** (:meth:`LoopClosureSearch.match`). The *old map* is keyframe
   ``a`` and its ``old_map_keyframes`` neighbours on each side moved into
   ``a``'s frame (built once per ``a`` and cached: a
   :class:`~bagtools.scan_matching.CorrelativeReference` and an
   :class:`~bagtools.scan_matching.NdtReference`); the *new map* is ``b`` and its
   ``new_map_keyframes`` predecessors moved into ``b``'s frame (several scans:
   a 180-degree laser's one scan sees too little to tell a corridor's places
   apart). :func:`~bagtools.scan_matching.match_scans_grid` searches a window around the
   estimated relative pose, +- ``gate_sigmas`` sigmas (at least
   ``min_window_m``/``min_window_rad``, at most the search radius and a full
   turn), in steps of ``resolution_m`` and of the angle that moves a point
   ``angular_reach_m`` away by one step; NDT (``ndt_cell_m`` cells, widened
   model) refines the best pose and must stay within
   ``max_refine_m``/``max_refine_rad`` of it. Wide windows (``wide_window_m``
   and more: the estimate is unsure) cost tens of milliseconds: at most one is
   searched per ``wide_spacing_m`` of path. Last, the two maps must not
   contradict each other's free space (:mod:`bagtools.grid.freespace`): the
   score counts points on walls, not walls standing where the other map's
   laser saw through. A look-alike (a room of the same shape furnished
   otherwise, a corridor a few metres along) can score as well as the place.
   In a wide window (``wide_window_m`` and more) the search asks for it: a
   window where another place scores ``global_unique_ratio`` of the best is
   refused (``LoopOutcome.LOOK_ALIKE``), as the global search's is; a second match cannot
   tell the two apart, since a corridor's look-alike shifts every match of it
   alike. A look-alike also puts walls in both maps' open space; a world that changed between the
   visits (a door shut, a person passing) contradicts one map only. So a match
   where more than ``max_seen_through`` of each map's points lie where the
   other saw through is refused (``LoopOutcome.SEES_THROUGH``).
3. **Covariance** (:func:`loop_covariance`): the ambiguity of the correlative
   search (Olson's likelihood-weighted spread around the best pose), the
   inverse NDT Hessian (large along a corridor, where the match is weak), the
   laser odometry's floor, and the uncertainty of the two local maps, which the
   odometry chain assembled (its edges' covariances propagated to each map's
   centre keyframe).
4. **Acceptance** (:class:`~bagtools.pose_graph.consistency.ConsistencyCheck`): a score of at least
   ``min_score``; and the match must agree with the current estimate within
   the gate. When the estimate is sure of the relative pose (``sigma_t`` at
   most ``sure_sigma_m``) that is enough. Otherwise one match proves little (a
   corridor or a symmetric room matches in several places), and the match
   waits up to ``pending_keyframes`` keyframes for a second, from a new keyframe
   whose new map shares none of its keyframes (two matches of the same scans
   are one piece of evidence: a look-alike fools both), that is pairwise
   consistent with it (the cycle loop 1, old chain, loop 2, new chain closes
   within the gate: E. Olson's single-cluster test in its smallest form); both
   are then accepted. Unconfirmed matches are rejected. A match waiting is
   also **followed up** (see step 5) when its window was wide
   (``wide_window_m`` and more), spanned at least ``COVER_SIGMAS`` of the
   estimate's uncertainty (not cut short by the search radius) and held no
   look-alike (as step 5 asks of a global match): each later keyframe whose
   new map shares none of its keyframes is matched in a small window around
   where the match puts it. A follow-up repeats the error of a wrong match (a
   corridor's look-alike, a place outside a window cut short, or a narrow
   window's best but wrong pose), so other matches wait for an independent
   second one; and in the back end's outlier check a follow-up and its match
   are one piece of evidence, not two (:meth:`ConsistencyCheck.supported`).

5. **Global search** (:meth:`LoopClosureSearch.global_due`,
   :meth:`LoopClosureSearch.global_tiles`): the search above trusts the
   estimate to within its gate, which after a long loop or one bad step it is
   not. So once the robot has gone ``global_after_m`` of path without an
   accepted loop (and again every ``global_after_m`` while none comes), the new
   keyframe is matched against old maps anywhere, whatever the estimate says
   (W. Hess et al.'s global constraint search, at a sampling ratio): one old
   map per ``global_tile_m`` of old path, the ``global_max_tiles`` nearest in
   the estimate at most, each searched over +- ``global_window_m`` around the
   old keyframe and every heading by the branch and bound, which
   ``global_min_score`` prunes early. A match is kept only if no other place
   of its window (``global_separation_m``/``_rad`` away) scores
   ``global_unique_ratio`` of it: a corridor or a symmetric room matches in
   several places, a look-alike as well as the place. It is checked against
   the estimate only loosely: it may correct it by up to
   ``global_gate_sigmas`` of the drift model's uncertainty of the relative
   pose (graph distance times the drift rates, as in step 1), which after a
   long loop is metres and tens of degrees, but rules out a look-alike a few
   metres from where a short stretch of path puts the robot. The best match
   waits (``PENDING``) for a **follow-up**: each later keyframe whose new map
   shares none of its keyframes is matched in a small window around where
   that match puts it (the old chain, the match, the new chain); a follow-up
   at ``min_score`` that is pairwise consistent confirms both.

Every candidate is recorded as a :class:`LoopCandidate` with what happened to it.
"""

from __future__ import annotations

import math
import time
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np

from bagtools.scan_matching import (
    MIN_SCAN_POINTS, CorrelativeReference, GridMatchResult, NdtReference, match_scans, match_scans_grid,
    match_scans_grid_peaks, voxel_subsample,
)
from bagtools.scan_matching.covariance import COVARIANCE_FLOOR, information_inverse
from bagtools.grid.freespace import FreeSpace
from bagtools.pose_graph.loops import LoopCandidate, LoopKind, LoopOptions, LoopOutcome
from bagtools.transforms import se2_between, se2_compose

#: A local match is followed up only when its window spans at least this many sigmas of the estimate's uncertainty
#: (95 % of where the place can be): beyond that, a match that is unique in its window may be a look-alike of a
#: place outside it.
COVER_SIGMAS = 2.0



def _compose_with_covariance(a: np.ndarray, a_cov: np.ndarray, b: np.ndarray,
                             b_cov: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """a then b ([x, y, theta]) and the covariance of the result (first order, a and b independent)."""
    c, s = math.cos(a[2]), math.sin(a[2])
    J_a = np.array([[1.0, 0.0, -s * b[0] - c * b[1]], [0.0, 1.0, c * b[0] - s * b[1]], [0.0, 0.0, 1.0]])
    J_b = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return se2_compose(a, b), J_a @ a_cov @ J_a.T + J_b @ b_cov @ J_b.T


def _inverse_with_covariance(m: np.ndarray, m_cov: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The inverse of the motion m ([x, y, theta]) and its covariance (first order)."""
    c, s = math.cos(m[2]), math.sin(m[2])
    J = np.array([[-c, -s, s * m[0] - c * m[1]], [s, -c, c * m[0] + s * m[1]], [0.0, 0.0, -1.0]])
    inverse = np.array([-(c * m[0] + s * m[1]), s * m[0] - c * m[1], -m[2]])
    return inverse, J @ m_cov @ J.T


def _adjoint(T: np.ndarray) -> np.ndarray:
    """SE(2) adjoint of T = [x, y, theta]: maps a perturbation on the left of T to one on its right, inverted."""
    c, s = math.cos(T[2]), math.sin(T[2])
    return np.array([[c, -s, T[1]], [s, c, -T[0]], [0.0, 0.0, 1.0]])


def ndt_information_inverse(hessian: np.ndarray) -> np.ndarray:
    """Inverse of an NDT Hessian (3,3) on its positive eigenvalues; a direction without curvature gets 1e2."""
    return information_inverse(0.5 * (hessian + hessian.T))


def loop_covariance(grid: GridMatchResult, ndt_hessian: np.ndarray, T_old_new: np.ndarray,
                    old_map_covariance: np.ndarray, new_map_covariance: np.ndarray) -> np.ndarray:
    """Covariance (3,3) of a loop match ``T_old_new`` refined by NDT (m^2, m rad, rad^2; new keyframe's frame).

    The sum of: the spread of the likelihood among the correlative candidates
    around the best (Olson's covariance without its discretization term
    step^2 / 12, which the NDT refinement removes): large where the match is
    ambiguous; the inverse NDT Hessian (the refinement's own precision);
    :data:`COVARIANCE_FLOOR`, the laser odometry's floor for its edges; and the
    uncertainty of the two local maps, assembled from keyframes placed by the
    odometry chain (:meth:`LoopClosureSearch.map_covariance`; the old map's
    moved into the new keyframe's frame).
    """
    discretization = np.diag([grid.resolution_m**2, grid.resolution_m**2, grid.angular_resolution_rad**2]) / 12.0
    values, vectors = np.linalg.eigh(grid.covariance - discretization)
    spread = (vectors * np.maximum(values, 0.0)) @ vectors.T
    back = np.linalg.inv(_adjoint(T_old_new))
    return (spread + ndt_information_inverse(ndt_hessian) + COVARIANCE_FLOOR + back @ old_map_covariance @ back.T
            + new_map_covariance)


@dataclass
class _OldMap:
    correlative: CorrelativeReference
    ndt: NdtReference
    covariance: np.ndarray  # of the map's assembly, see LoopClosureSearch.map_covariance
    scans: list[tuple[np.ndarray, np.ndarray]]  # its keyframes' (base position, points) in the old keyframe's frame
    points: np.ndarray  # the scans' points, stacked (M,2)
    free: FreeSpace | None = None  # built when a match first needs it (see LoopClosureSearch._seen_through)


class LoopClosureSearch:
    """Candidates and matches for loop closure over the keyframes seen so far (see the module docstring).

    Args:
        options: the search settings.
    """

    def __init__(self, options: LoopOptions | None = None) -> None:
        self.options = options or LoopOptions()
        self.points: list[np.ndarray] = []  # per keyframe: returns within max_range_m, base frame
        self.path_m: list[float] = []  # per keyframe: distance along the path from the first, metres
        self.motions: list[np.ndarray] = []  # per keyframe: [x, y, theta] from the previous keyframe
        self.motion_covariances: list[np.ndarray] = []  # and its covariance
        self._last_wide_m = -math.inf  # path length at the last wide search
        self._last_global_m = -math.inf  # path length at the last global search
        self._cache: OrderedDict[int, _OldMap] = OrderedDict()

    def add_keyframe(self, points_base: np.ndarray, motion: np.ndarray | None,
                     motion_covariance: np.ndarray | None = None) -> None:
        """Record keyframe ``len(self.points)``: its points (N,2) in its base frame, and its motion [x, y, theta]
        from the previous keyframe with that motion's covariance (None for the first keyframe)."""
        pts = np.asarray(points_base, dtype=np.float64).reshape(-1, 2)
        pts = pts[np.isfinite(pts).all(axis=1)]
        pts = pts[np.einsum("ij,ij->i", pts, pts) <= self.options.max_range_m**2]
        self.points.append(pts)
        self.motions.append(np.zeros(3) if motion is None else np.asarray(motion, dtype=np.float64))
        self.motion_covariances.append(np.zeros((3, 3)) if motion_covariance is None
                                       else np.asarray(motion_covariance, dtype=np.float64))
        step = 0.0 if motion is None else float(np.hypot(motion[0], motion[1]))
        self.path_m.append((self.path_m[-1] if self.path_m else 0.0) + step)

    def map_covariance(self, centre: int, keyframes: range) -> np.ndarray:
        """How uncertain a local map is (3,3, centre keyframe's frame): the mean over its keyframes of the
        covariance of their pose relative to ``centre``, propagated along the chain of motions (first order)."""
        total = np.zeros((3, 3))
        for direction in (1, -1):
            pose, cov = np.zeros(3), np.zeros((3, 3))
            k = centre
            while (k + direction) in keyframes:
                if direction == 1:
                    m, m_cov = self.motions[k + 1], self.motion_covariances[k + 1]
                else:  # the motion from k to k - 1 is the inverse of keyframe k's
                    m, m_cov = _inverse_with_covariance(self.motions[k], self.motion_covariances[k])
                pose, cov = _compose_with_covariance(pose, cov, m, m_cov)
                total += cov
                k += direction
        return total / max(len(keyframes), 1)

    # -- candidates ------------------------------------------------------------------------------

    def sigmas(self, graph_distance_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Relative-pose uncertainty (m, rad) of nodes at graph distances ``graph_distance_m`` (m)."""
        o = self.options
        d = np.asarray(graph_distance_m, dtype=np.float64)
        return o.drift_per_m * d, o.drift_rad_per_m * d

    def candidates(self, new: int, poses: np.ndarray, graph_distance_m: np.ndarray,
                   recent_loops: list[tuple[int, int]]) -> list[int]:
        """Old keyframes to match against keyframe ``new`` (nearest first).

        ``poses`` (N,3): the current estimate of every keyframe so far;
        ``graph_distance_m`` (N,): each one's graph distance to ``new``;
        ``recent_loops``: (old, new) node pairs of accepted loops.
        """
        o = self.options
        path = np.asarray(self.path_m)
        old = self._far_back(new)
        if old.size == 0:
            return []
        dist = np.hypot(*(poses[old, :2] - poses[new, :2]).T)
        sigma_t = self.sigmas(graph_distance_m)[0]
        reach = dist <= o.search_radius_m + o.gate_sigmas * sigma_t[old]
        old, dist = old[reach], dist[reach]
        if old.size == 0:
            return []
        # Runs of consecutive keyframes: one pass through the place each.
        breaks = np.flatnonzero(np.diff(old) > 1) + 1
        picks = []
        for run, d in zip(np.split(old, breaks), np.split(dist, breaks)):
            if self._tied(run, new, recent_loops):
                continue
            picks.append((float(d.min()), int(run[np.argmin(d)])))
        picks.sort()
        chosen: list[int] = []
        for _, a in picks:
            if len(chosen) == o.max_candidates:
                break
            if self.window((float(sigma_t[a]), 0.0))[0] >= o.wide_window_m:
                if path[new] - self._last_wide_m < o.wide_spacing_m:
                    continue
                self._last_wide_m = float(path[new])
            chosen.append(a)
        return chosen

    def _far_back(self, new: int) -> np.ndarray:
        """Old keyframes ``new`` may close a loop with: at least ``min_travel_m`` back along the path, and far
        enough back in the chain that the two local maps share no keyframe (else the match repeats the chain)."""
        o = self.options
        path = np.asarray(self.path_m)
        last = new - o.new_map_keyframes - o.old_map_keyframes - 1
        return np.flatnonzero(path[new] - path[: max(last, 0)] >= o.min_travel_m)

    def _tied(self, run: np.ndarray, new: int, loops: list[tuple[int, int]]) -> bool:
        """True if an accepted loop from the last ``loop_spacing_m`` of path already lands in (or next to) ``run``."""
        o = self.options
        path = self.path_m
        lo, hi = path[int(run[0])] - o.search_radius_m, path[int(run[-1])] + o.search_radius_m
        return any(path[new] - path[b] < o.loop_spacing_m and lo <= path[a] <= hi for a, b in loops)

    def global_due(self, new: int, last_loop_new: int | None) -> bool:
        """Is a global search due at keyframe ``new``? Yes once ``global_after_m`` of path has passed since both
        the last accepted loop (its new keyframe ``last_loop_new``, None for none) and the last global search;
        a yes counts as that search (the next one is due ``global_after_m`` later)."""
        o = self.options
        path = self.path_m
        since_loop = path[new] - (path[last_loop_new] if last_loop_new is not None else 0.0)
        if since_loop < o.global_after_m or path[new] - self._last_global_m < o.global_after_m:
            return False
        self._last_global_m = path[new]
        return True

    def global_tiles(self, new: int, poses: np.ndarray) -> list[int]:
        """Old keyframes to search globally from ``new``: one per ``global_tile_m`` of old path (the middle one),
        far enough back as for :meth:`candidates`, the ``global_max_tiles`` nearest in the estimate ``poses``."""
        o = self.options
        path = np.asarray(self.path_m)
        old = self._far_back(new)
        if old.size == 0:
            return []
        tile = np.floor(path[old] / o.global_tile_m).astype(np.int64)
        starts = np.flatnonzero(np.r_[True, np.diff(tile) != 0])
        ends = np.r_[starts[1:], old.size]
        middles = old[(starts + ends - 1) // 2]
        dist = np.hypot(*(poses[middles, :2] - poses[new, :2]).T)
        return [int(a) for a in middles[np.argsort(dist, kind="stable")][: o.global_max_tiles]]

    # -- matching --------------------------------------------------------------------------------

    def _old_map(self, old: int, poses: np.ndarray, cache: bool = True) -> _OldMap:
        """The old map around ``old`` (see the module docstring); built once and kept in the LRU cache, unless
        ``cache`` is False (a global search's tiles, which must not push out the maps local searches reuse)."""
        cached = self._cache.get(old)
        if cached is not None:
            if cache:
                self._cache.move_to_end(old)
            return cached
        o = self.options
        keyframes = self._old_range(old)
        scans = self._placed(keyframes, poses, poses[old])
        points = np.vstack([p for _, p in scans])
        built = _OldMap(CorrelativeReference.from_points(points, o.resolution_m),
                        NdtReference.from_points(points, o.ndt_cell_m, "widened"), self.map_covariance(old, keyframes),
                        scans, points)
        if not cache:
            return built
        self._cache[old] = built
        if len(self._cache) > o.cache_size:
            self._cache.popitem(last=False)
        return built

    def window(self, sigma: tuple[float, float]) -> np.ndarray:
        """Search half-widths (m, m, rad) for an estimate of uncertainty ``sigma`` (m, rad)."""
        o = self.options
        half_m = min(max(o.gate_sigmas * sigma[0], o.min_window_m), o.search_radius_m)
        return np.array([half_m, half_m, min(max(o.gate_sigmas * sigma[1], o.min_window_rad), math.pi)])

    def angular_step(self, reach_m: float) -> float:
        """Rotation step of the search (rad): a point ``reach_m`` from the keyframe moves by one raster cell."""
        return self.options.resolution_m / max(reach_m, self.options.resolution_m)

    def _old_range(self, old: int) -> range:
        """The keyframes of the old map around ``old``."""
        k = self.options.old_map_keyframes
        return range(max(0, old - k), min(len(self.points), old + k + 1))

    def _new_range(self, new: int) -> range:
        """The keyframes of the new map: ``new`` and the ones before it."""
        return range(max(0, new - self.options.new_map_keyframes), new + 1)

    def _new_map(self, scans: list[tuple[np.ndarray, np.ndarray]]) -> np.ndarray:
        """The new map's points (``scans`` placed by :meth:`_placed`), thinned to at most ``max_points``."""
        o = self.options
        points = np.vstack([p for _, p in scans])
        voxel = o.resolution_m
        thinned = voxel_subsample(points, voxel)
        while len(thinned) > o.max_points:
            voxel *= 1.5
            thinned = voxel_subsample(points, voxel)
        return thinned

    def _placed(self, keyframes: range, poses: np.ndarray, frame_pose: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
        """Each of ``keyframes`` in the frame of the pose ``frame_pose`` (estimate): (its base's position (2,),
        its points (N,2))."""
        out = []
        for k in keyframes:
            T = se2_between(frame_pose, poses[k])
            c, s = math.cos(T[2]), math.sin(T[2])
            out.append((T[:2], self.points[k] @ np.array([[c, s], [-s, c]]) + T[:2]))
        return out

    def _seen_through(self, old_map: _OldMap, new_scans: list[tuple[np.ndarray, np.ndarray]],
                      T_old_new: np.ndarray) -> float:
        """How much the two maps, matched at ``T_old_new``, contradict each other's free space: the smaller of the
        shares of each map's points that fall where the other's rays passed (see :mod:`bagtools.grid.freespace`).
        The smaller, because a world that changed between the visits (a door shut, a person passing) puts walls
        in one map's free space, while a look-alike puts them in both. ``new_scans``: the new map's, placed by
        :meth:`_placed`."""
        resolution = self.options.resolution_m
        if old_map.free is None:
            old_map.free = FreeSpace.from_scans(old_map.scans, resolution)
        new_free = FreeSpace.from_scans(new_scans, resolution)
        new_points = np.vstack([points for _, points in new_scans])
        c, s = math.cos(T_old_new[2]), math.sin(T_old_new[2])
        R = np.array([[c, s], [-s, c]])
        return min(old_map.free.seen_through(new_points @ R + T_old_new[:2]),
                   new_free.seen_through((old_map.points - T_old_new[:2]) @ R.T))

    def match(self, old: int, new: int, poses: np.ndarray, sigma: tuple[float, float],
              guess: np.ndarray | None = None, kind: LoopKind = LoopKind.LOCAL) -> LoopCandidate:
        """Match keyframe ``new`` against the old map around ``old``; the record.

        ``sigma``: the uncertainty (m, rad) of the relative pose ``guess`` of
        ``new`` in ``old``'s frame (default: from the estimate ``poses``),
        which sizes the window. ``kind=LoopKind.GLOBAL`` searches +- ``global_window_m``
        around ``old`` itself and every heading, with ``global_min_score``.
        """
        o = self.options
        t0 = time.perf_counter()
        min_score = o.min_score
        if kind == LoopKind.GLOBAL:
            guess, window, min_score = np.zeros(3), np.array([o.global_window_m, o.global_window_m, math.pi]), \
                o.global_min_score
        else:
            guess = se2_between(poses[old], poses[new]) if guess is None else np.asarray(guess, dtype=np.float64)
            window = self.window(sigma)
        cand = LoopCandidate(old, new, guess, window, (float(sigma[0]), float(sigma[1])), kind=kind)
        old_map = self._old_map(old, poses, cache=kind != LoopKind.GLOBAL)
        new_scans = self._placed(self._new_range(new), poses, poses[new])
        current = self._new_map(new_scans)
        reach = min(math.sqrt(float(np.einsum("ij,ij->i", current, current).max(initial=0.0))), o.angular_reach_m)
        search = dict(initial_pose=guess, search_range=window, angular_resolution_rad=self.angular_step(reach),
                      min_score=min_score)
        if kind == LoopKind.GLOBAL or window[0] >= o.wide_window_m:
            # anywhere in the map, or a window wide enough to hold a corridor's look-alikes: is the place the
            # window's one good match?
            peaks = match_scans_grid_peaks(current, old_map.correlative, max_peaks=2, min_ratio=o.global_unique_ratio,
                                           separation=(o.global_separation_m, o.global_separation_rad), **search)
            # uniqueness in a window capped (at the search radius or a full turn) short of COVER_SIGMAS of the
            # estimate's uncertainty says little of the places outside it: such a match is not followed up
            capped = bool(window[0] < COVER_SIGMAS * sigma[0] or window[2] < COVER_SIGMAS * sigma[1])
            cand.look_alike = len(peaks) > 1 or (kind != LoopKind.GLOBAL and capped)
            # Another place scoring as well is refused, local or global: an independent second match cannot
            # tell the two apart (a corridor's look-alike shifts every match of it alike, and the chains between
            # them allow metres after a long loop), so a pair of look-alikes would enter the graph and bend it.
            if len(peaks) != 1:  # none: nothing scores global_min_score (the search is not run again for why)
                too_few = min(len(current), old_map.correlative.n_points) < MIN_SCAN_POINTS
                cand.status = (LoopOutcome.LOOK_ALIKE if peaks else LoopOutcome.TOO_FEW_POINTS if too_few
                               else LoopOutcome.LOW_SCORE)
                cand.score = float(peaks[0].score) if peaks else 0.0
                cand.time_s = time.perf_counter() - t0
                return cand
            grid = peaks[0]
        else:
            grid = match_scans_grid(current, old_map.correlative, **search)
        if not grid.ok:
            cand.status = LoopOutcome.TOO_FEW_POINTS if "too few" in grid.reason else LoopOutcome.LOW_SCORE
            cand.time_s = time.perf_counter() - t0
            return cand
        ndt = match_scans(current, old_map.ndt, initial_pose=grid.pose, max_iterations=50)
        moved = se2_between(grid.pose, ndt.pose)
        cand.score = float(grid.score)
        if ndt.score <= 0 or np.hypot(moved[0], moved[1]) > o.max_refine_m or abs(moved[2]) > o.max_refine_rad:
            cand.status = LoopOutcome.REFINE_FAILED
        elif self._seen_through(old_map, new_scans, ndt.pose) > o.max_seen_through:
            cand.status = LoopOutcome.SEES_THROUGH
        else:
            cand.T_old_new = ndt.pose
            cand.covariance = loop_covariance(grid, ndt.hessian, ndt.pose, old_map.covariance,
                                              self.map_covariance(new, self._new_range(new)))
        cand.time_s = time.perf_counter() - t0
        return cand
