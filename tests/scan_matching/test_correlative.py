"""Correlative scan matching (match_scans_grid) on synthetic LDS-01 scan pairs in the TurtleBot3 world."""

from __future__ import annotations

import numpy as np
import pytest

from bagtools.scan_matching import (
    CorrelativeReference,
    GridMatchResult,
    match_scans,
    match_scans_grid,
    match_scans_grid_peaks,
    match_scans_grid_ranges,
    ranges_to_points,
)
from bagtools.scan_matching import correlative, window_search
from bench.bench_ndt import edt_raster
from bench.scan_pairs import ANGLES_RAD, lds01_ranges, relative_pose, scan_pairs, turtlebot3_world

TRANS_TOL_M = 0.02
ROT_TOL_RAD = np.radians(0.5)
WINDOW = (0.3, 0.3, 0.3)


@pytest.fixture(scope="module")
def pairs():
    return scan_pairs(10, seed=21)


def pose_error(estimate: np.ndarray, truth: np.ndarray) -> tuple[float, float]:
    d = estimate - truth
    return float(np.hypot(d[0], d[1])), float(abs((d[2] + np.pi) % (2 * np.pi) - np.pi))


def in_parent(points: np.ndarray, pose) -> np.ndarray:
    """Points given in a frame whose pose in a parent frame is ``pose``, in the parent frame: R p + t."""
    c, s = np.cos(pose[2]), np.sin(pose[2])
    return points @ np.array([[c, s], [-s, c]]) + np.asarray(pose[:2])


def in_child(points: np.ndarray, pose) -> np.ndarray:
    """The inverse of :func:`in_parent`: R^T (p - t)."""
    c, s = np.cos(pose[2]), np.sin(pose[2])
    return (points - np.asarray(pose[:2])) @ np.array([[c, -s], [s, c]])


def assert_same_candidate(a: GridMatchResult, b: GridMatchResult) -> None:
    assert a.ok and b.ok, (a.reason, b.reason)
    assert a.index == b.index
    assert a.score == b.score
    np.testing.assert_array_equal(a.pose, b.pose)


def test_branch_and_bound_equals_exhaustive_search(pairs):
    for pair in pairs[:5]:
        reference = CorrelativeReference.from_points(pair.reference_points)
        bnb = match_scans_grid(pair.current_points, reference, search_range=WINDOW)
        full = match_scans_grid(pair.current_points, reference, search_range=WINDOW, method="exhaustive")
        assert_same_candidate(bnb, full)
        np.testing.assert_array_equal(bnb.covariance, full.covariance)
        n_angles = 2 * int(np.floor(0.3 / bnb.angular_resolution_rad + 1e-9)) + 1
        assert full.n_evaluated == full.n_candidates == bnb.n_candidates == n_angles * 13 * 13
        assert bnb.n_evaluated < full.n_evaluated / 5


@pytest.mark.parametrize("offset", [(0.3, 0.0, 0.0), (0.0, -0.3, 0.0), (0.0, 0.0, 0.3), (0.45, -0.4, -0.35),
                                    (0.3, 0.3, 0.3)])
def test_optimum_on_the_window_edge_equals_exhaustive(pairs, offset):
    # The truth on or beyond the border of the window: the best candidate lies on the edge.
    pair = pairs[1]
    initial = pair.truth + offset
    bnb = match_scans_grid(pair.current_points, pair.reference_points, initial_pose=initial, search_range=WINDOW)
    full = match_scans_grid(pair.current_points, pair.reference_points, initial_pose=initial, search_range=WINDOW,
                            method="exhaustive")
    assert_same_candidate(bnb, full)
    half_widths = np.array([np.floor(0.3 / bnb.angular_resolution_rad + 1e-9), 6, 6])
    assert np.any(np.abs(bnb.index) == half_widths), (bnb.index, half_widths)


def random_scene(rng: np.random.Generator) -> np.ndarray:
    """Points on a few random segments and circles, metres."""
    parts = []
    for _ in range(rng.integers(2, 6)):
        a, b = rng.uniform(-3, 3, 2), rng.uniform(-3, 3, 2)
        t = rng.uniform(0, 1, rng.integers(10, 40))[:, None]
        parts.append(a + t * (b - a))
    for _ in range(rng.integers(0, 3)):
        c, r = rng.uniform(-2, 2, 2), rng.uniform(0.1, 0.5)
        phi = rng.uniform(0, 2 * np.pi, rng.integers(8, 30))
        parts.append(c + r * np.column_stack((np.cos(phi), np.sin(phi))))
    return np.concatenate(parts)


@pytest.mark.parametrize("seed", range(40))
def test_randomized_branch_and_bound_equals_exhaustive(seed):
    rng = np.random.default_rng(seed)
    reference = random_scene(rng)
    if seed % 5 == 0:  # grid-aligned points, no noise: many exact ties, broken the same way by both
        reference = np.round(reference / 0.1) * 0.1
    truth = np.array([*rng.uniform(-0.4, 0.4, 2), rng.uniform(-0.5, 0.5)])
    current = in_child(reference[: max(5, len(reference) * 2 // 3)], truth)
    if seed % 5:
        current = current + rng.normal(0, 0.01, current.shape)
    kwargs = {
        "initial_pose": truth + rng.uniform(-0.2, 0.2, 3),
        "search_range": (rng.uniform(0, 0.6), rng.uniform(0, 0.6), rng.choice([0.0, rng.uniform(0, 0.6)])),
        "resolution_m": float(rng.choice([0.03, 0.05, 0.1])),
        "angular_resolution_rad": None if seed % 2 else rng.uniform(0.02, 0.08),
    }
    if seed % 7 == 3:  # every heading, coarser to keep the exhaustive search short
        kwargs.update(search_range=(0.5, 0.5, np.pi), resolution_m=0.1, angular_resolution_rad=0.05)
    bnb = match_scans_grid(current, reference, **kwargs)
    full = match_scans_grid(current, reference, method="exhaustive", **kwargs)
    assert bnb.ok and full.ok
    assert_same_candidate(bnb, full)


def test_full_turn_window_lists_every_heading_once(pairs):
    pair = pairs[2]
    result = match_scans_grid(pair.current_points, pair.reference_points, search_range=(0.0, 0.0, np.pi),
                              angular_resolution_rad=0.1)
    n_angles = int(np.ceil(2 * np.pi / 0.1))
    assert result.n_candidates == n_angles
    assert result.angular_resolution_rad == pytest.approx(2 * np.pi / n_angles)
    assert -np.pi <= result.pose[2] < np.pi


def test_grid_match_then_ndt_recovers_the_motion_from_zero(pairs):
    # The recipe: zero initial pose, +-0.3 m and +-0.3 rad, then NDT (widened, 0.5 m cells) seeded by it.
    for pair in pairs:
        grid = match_scans_grid(pair.current_points, pair.reference_points, search_range=WINDOW)
        assert grid.ok and 0.5 < grid.score <= 1.0
        trans, rot = pose_error(grid.pose, pair.truth)
        assert trans < 0.06 and rot < 3 * grid.angular_resolution_rad, (grid.pose, pair.truth)
        ndt = match_scans(pair.current_points, pair.reference_points, initial_pose=grid.pose, cell_size=0.5,
                          cell_model="widened")
        trans, rot = pose_error(ndt.pose, pair.truth)
        assert trans < TRANS_TOL_M and rot < ROT_TOL_RAD


def test_pose_convention_matches_match_scans():
    # As MATLAB: currScan = transformScan(refScan, [0.2 -0.1 0]) moves every point by (0.2, -0.1);
    # the match maps the current scan back onto the reference: pose (-0.2, 0.1, 0).
    rng = np.random.default_rng(0)
    reference = ranges_to_points(2.0 + 0.5 * np.sin(3 * ANGLES_RAD) + rng.normal(0, 0.002, 360), ANGLES_RAD)
    result = match_scans_grid(reference + (0.2, -0.1), reference, search_range=WINDOW)
    np.testing.assert_allclose(result.pose, [-0.2, 0.1, 0.0], atol=1e-9)
    assert result.index == (0, -4, 2)
    # and p_ref = R(theta) p_cur + t with a rotation, to within one step
    truth = np.array([0.1, -0.05, 0.2])
    result = match_scans_grid(in_child(reference, truth), reference, search_range=WINDOW)
    trans, rot = pose_error(result.pose, truth)
    assert trans <= 0.05 and rot <= result.angular_resolution_rad


def test_scan_against_itself_scores_one_at_zero(pairs):
    points = pairs[3].reference_points
    result = match_scans_grid(points, points, initial_pose=(0.1, -0.1, 0.1), search_range=WINDOW,
                              angular_resolution_rad=0.02)
    np.testing.assert_allclose(result.pose, 0.0, atol=1e-9)
    assert result.score == 1.0 and result.index == (-5, -2, 2)


def local_map_case(seed: int):
    """A local map (5 scans from nearby poses, in the first scan's frame), a scan from up to 1 m away at any heading."""
    world = turtlebot3_world()
    rng = np.random.default_rng(seed)
    origin = np.array([-0.7, 0.2, 0.4])
    poses = [origin + (0.15 * k, 0.05 * k, 0.1 * k) for k in range(5)]
    scans = [in_parent(ranges_to_points(lds01_ranges(world, p, rng), ANGLES_RAD), relative_pose(origin, p))
             for p in poses]
    current_pose = np.array([-0.2, -0.4, rng.uniform(-np.pi, np.pi)])
    current = ranges_to_points(lds01_ranges(world, current_pose, rng), ANGLES_RAD)
    return np.concatenate(scans), current, relative_pose(origin, current_pose)


def test_wide_window_against_a_local_map_finds_the_pose():
    # The TurtleBot3 world is nearly symmetric under a half turn: with every heading in the window the mirrored
    # pose often scores a little higher than the true one, so the heading is known to +-pi/2 here.
    reference_points, current, truth = local_map_case(4)
    reference = CorrelativeReference.from_points(reference_points)
    result = match_scans_grid(current, reference, initial_pose=(0.0, 0.0, truth[2] + 0.4),
                              search_range=(4.0, 4.0, np.pi / 2))
    assert result.ok and result.n_evaluated < result.n_candidates / 100
    trans, rot = pose_error(result.pose, truth)
    assert trans < 0.06 and rot < 3 * result.angular_resolution_rad, (result.pose, truth)


def test_wide_window_equals_exhaustive_at_a_coarse_resolution():
    reference_points, current, truth = local_map_case(5)
    kwargs = {"initial_pose": truth + (0.6, -0.5, 2.0), "search_range": (1.0, 1.0, np.pi), "resolution_m": 0.1}
    bnb = match_scans_grid(current, reference_points, **kwargs)
    full = match_scans_grid(current, reference_points, method="exhaustive", **kwargs)
    assert_same_candidate(bnb, full)
    trans, rot = pose_error(bnb.pose, truth)
    assert trans < 0.12 and rot < 3 * bnb.angular_resolution_rad


def test_prebuilt_reference_is_reused_across_windows(pairs):
    pair = pairs[4]
    reference = CorrelativeReference.from_points(pair.reference_points)
    for search in ((0.1, 0.1, 0.1), (0.6, 0.2, 0.3), (0.2, 0.2, 0.2), (1.0, 1.0, 0.1)):
        shared = match_scans_grid(pair.current_points, reference, search_range=search)
        fresh = match_scans_grid(pair.current_points, pair.reference_points, search_range=search)
        assert_same_candidate(shared, fresh)
    with pytest.raises(ValueError, match="differs from the prebuilt reference"):
        match_scans_grid(pair.current_points, reference, resolution_m=0.1)


def test_covariance_is_a_covariance_with_the_discretization_floor(pairs):
    for pair in pairs[:4]:
        result = match_scans_grid(pair.current_points, pair.reference_points, search_range=WINDOW)
        cov = result.covariance
        np.testing.assert_allclose(cov, cov.T)
        floor = np.array([0.05**2, 0.05**2, result.angular_resolution_rad**2]) / 12
        assert np.all(np.diag(cov) >= floor * (1 - 1e-9))
        assert np.linalg.eigvalsh(cov).min() > 0


def test_covariance_is_wide_along_a_corridor():
    # A scan of 6 m of a long corridor: sliding along the walls changes nothing, across them everything.
    def corridor(half_length: float) -> np.ndarray:
        x = np.arange(-half_length, half_length, 0.02)
        return np.concatenate([np.column_stack((x, np.full_like(x, y))) for y in (-1.0, 1.0)])

    result = match_scans_grid(corridor(3.0), corridor(6.0), search_range=WINDOW)
    assert result.ok
    assert result.covariance[0, 0] > 10 * result.covariance[1, 1]
    np.testing.assert_allclose(result.pose, 0.0, atol=1e-9)  # of the equal candidates along it, the initial pose


def test_min_score(pairs):
    pair = pairs[5]
    plain = match_scans_grid(pair.current_points, pair.reference_points, search_range=WINDOW)
    pruned = match_scans_grid(pair.current_points, pair.reference_points, search_range=WINDOW,
                              min_score=plain.score - 0.1)
    assert_same_candidate(plain, pruned)
    assert pruned.n_evaluated <= plain.n_evaluated
    failed = match_scans_grid(pair.current_points, pair.reference_points, search_range=WINDOW,
                              min_score=min(1.0, plain.score + 0.01), initial_pose=(0.1, 0.0, 0.0))
    assert not failed.ok and "min_score" in failed.reason
    np.testing.assert_array_equal(failed.pose, [0.1, 0.0, 0.0])


def test_ranges_variant_equals_points_variant(pairs):
    pair = pairs[6]
    ranges = pair.current_ranges.copy()
    ranges[::9] = np.nan
    ranges[4] = 0.0
    by_ranges = match_scans_grid_ranges(ranges, ANGLES_RAD, pair.reference_ranges, ANGLES_RAD, search_range=WINDOW)
    by_points = match_scans_grid(ranges_to_points(ranges, ANGLES_RAD), pair.reference_points, search_range=WINDOW)
    assert_same_candidate(by_ranges, by_points)
    assert by_ranges.n_points == np.sum(np.isfinite(ranges) & (ranges > 0))


def test_non_finite_and_far_points_are_dropped(pairs):
    pair = pairs[7]
    current = pair.current_points.copy()
    current[::4] = np.nan
    result = match_scans_grid(current, pair.reference_points, search_range=WINDOW)
    assert result.ok and result.n_points == np.isfinite(current).all(axis=1).sum()
    near = match_scans_grid(current, pair.reference_points, search_range=WINDOW, max_range_m=2.0)
    keep = np.isfinite(current).all(axis=1) & (np.hypot(current[:, 0], current[:, 1]) <= 2.0)
    assert near.n_points == keep.sum()
    assert_same_candidate(near, match_scans_grid(current[keep], pair.reference_points, search_range=WINDOW))


@pytest.mark.parametrize(
    ("current", "reference", "reason"),
    [
        (np.full((360, 2), np.nan), "ok", "too few valid points in the current scan"),
        (np.zeros((0, 2)), "ok", "too few valid points in the current scan"),
        (np.array([[1.0, 0.0], [0.0, 1.0], [1.0, 1.0], [2.0, 2.0]]), "ok", "too few valid points in the current scan"),
        ("ok", np.full((360, 2), np.inf), "too few valid points in the reference scan"),
        ("ok", np.array([[1.0, 0.0], [0.0, 1.0]]), "too few valid points in the reference scan"),
        ("far", "ok", "no current point lands near the reference"),
    ],
)
def test_degenerate_input_fails_cleanly(pairs, current, reference, reason):
    pair = pairs[0]
    if isinstance(current, str):
        current = pair.current_points + (100.0, 0.0) if current == "far" else pair.current_points
    if isinstance(reference, str):
        reference = pair.reference_points
    result = match_scans_grid(current, reference, initial_pose=(0.1, 0.2, 0.3), search_range=WINDOW)
    assert isinstance(result, GridMatchResult)
    assert not result.ok and not result.converged
    assert reason in result.reason
    np.testing.assert_array_equal(result.pose, [0.1, 0.2, 0.3])
    assert result.score == 0.0 and np.all(np.isinf(np.diag(result.covariance)))


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"initial_pose": (0.0, 0.0)}, "initial_pose"),
        ({"initial_pose": (0.0, np.nan, 0.0)}, "initial_pose"),
        ({"search_range": (0.3, 0.3)}, "search_range"),
        ({"search_range": (0.3, -0.3, 0.3)}, "search_range"),
        ({"resolution_m": 0.0}, "resolution_m"),
        ({"resolution_m": np.inf}, "resolution_m"),
        ({"angular_resolution_rad": -0.01}, "angular_resolution_rad"),
        ({"sigma_m": 0.0}, "sigma_m"),
        ({"max_range_m": 0.0}, "max_range_m"),
        ({"min_score": 1.5}, "min_score"),
        ({"method": "fast"}, "method"),
        ({"resolution_m": 1e-6}, "limit"),
        ({"angular_resolution_rad": 1e-9}, "limit"),
        ({"search_range": (1000.0, 1000.0, 0.1)}, "limit"),
    ],
)
def test_bad_parameters_raise(pairs, kwargs, message):
    kwargs = {"search_range": WINDOW} | kwargs
    with pytest.raises(ValueError, match=message):
        match_scans_grid(pairs[0].current_points, pairs[0].reference_points, **kwargs)


def test_bad_array_shapes_raise(pairs):
    with pytest.raises(ValueError, match="current points"):
        match_scans_grid(np.zeros((10, 3)), pairs[0].reference_points)
    with pytest.raises(ValueError, match="reference points"):
        match_scans_grid(pairs[0].current_points, np.zeros(10))


def test_max_pooled_levels_bound_the_raster(pairs):
    reference = CorrelativeReference.from_points(pairs[0].reference_points)
    pyramid = reference.pyramid(3, np.array([8, 8]), np.array([8, 8]))
    levels = pyramid.levels.reshape(4, *pyramid.shape)
    rng = np.random.default_rng(1)
    for _ in range(200):
        k = int(rng.integers(1, 4))
        i, j = rng.integers(0, pyramid.shape[0] - 8), rng.integers(0, pyramid.shape[1] - 8)
        assert levels[k, i, j] == levels[0, i:i + 2**k, j:j + 2**k].max()
    assert levels[0].sum() == reference.raster.astype(np.int64).sum()
    assert correlative.RASTER_MAX == reference.raster.max()




@pytest.mark.parametrize("seed", range(12))
def test_likelihood_raster_equals_the_cut_off_distance_transform(seed):
    """The stamped raster is the Euclidean distance transform's likelihood, cell for cell, cut off at the kernel's
    reach (scipy's EDT over the whole raster is the reference it replaced)."""
    rng = np.random.default_rng(seed)
    res = float(rng.choice([0.02, 0.05, 0.1, 0.5]))
    sigma = float(res * rng.choice([0.5, 1.0, 1.7, 3.0]))
    points = rng.normal(size=(int(rng.integers(1, 2000)), 2)) * rng.uniform(0.1, 300 * res)
    reference = CorrelativeReference.from_points(points, res, sigma)
    expected, origin = edt_raster(points, res, sigma)
    np.testing.assert_array_equal(reference.raster, expected)
    np.testing.assert_allclose(reference.origin, origin)
# -- match_scans_grid_peaks: the distinct good poses of a window ------------------------------------------

PEAK_KW = {"search_range": (1.0, 1.0, np.pi), "resolution_m": 0.1, "max_peaks": 6, "min_ratio": 0.5,
           "separation": (0.5, 0.3)}


def test_first_peak_is_the_exact_best_and_the_rest_are_distinct_and_good():
    reference_points, current, truth = local_map_case(5)
    initial = truth + (0.6, -0.5, 2.0)
    reference = CorrelativeReference.from_points(reference_points, resolution_m=0.1)
    peaks = match_scans_grid_peaks(current, reference, initial_pose=initial, **PEAK_KW)
    best = match_scans_grid(current, reference, initial_pose=initial, search_range=PEAK_KW["search_range"])
    assert_same_candidate(peaks[0], best)
    assert 2 <= len(peaks) <= PEAK_KW["max_peaks"]
    scores = [p.score for p in peaks]
    assert scores == sorted(scores, reverse=True) and scores[-1] >= PEAK_KW["min_ratio"] * scores[0]
    for i, a in enumerate(peaks):
        # each peak's score is its pose's score (a one-candidate window there says the same)
        alone = match_scans_grid(current, reference, initial_pose=a.pose, search_range=(0.0, 0.0, 0.0))
        assert alone.score == pytest.approx(a.score, abs=1e-12)
        for b in peaks[:i]:
            d = a.pose - b.pose
            far_m = np.hypot(d[0], d[1]) >= PEAK_KW["separation"][0] - 1e-9
            far_rad = abs((d[2] + np.pi) % (2 * np.pi) - np.pi) >= PEAK_KW["separation"][1] - 1e-9
            assert far_m or far_rad


def test_peaks_miss_no_good_place_of_the_window():
    """Every candidate scoring above the ratio (all of them scored, as the exhaustive search does) lies near a peak."""
    reference_points, current, truth = local_map_case(6)
    initial = truth + (0.3, 0.2, 1.0)
    kw = {**PEAK_KW, "search_range": (0.6, 0.6, np.pi), "max_peaks": 1000, "angular_resolution_rad": 0.05}
    peaks = match_scans_grid_peaks(current, reference_points, initial_pose=initial, **kw)
    prep = correlative._prepare(current, reference_points, initial, kw["search_range"], 0.1, 0.05, None, None, 0.0,
                                "exhaustive")
    na, nx, ny = prep.win.n
    a, ix, iy = (g.reshape(-1) for g in np.meshgrid(np.arange(na), np.arange(nx), np.arange(ny), indexing="ij"))
    sums = window_search.node_scores(prep.win, a, ix * prep.win.stride + iy, 0)
    good = sums >= np.ceil(kw["min_ratio"] * sums.max())
    xy = np.stack((initial[0] + (ix[good] - prep.win.steps[1]) * 0.1, initial[1] + (iy[good] - prep.win.steps[2]) * 0.1),
                  axis=1)
    theta = prep.win.angles[a[good]]
    near_any = np.zeros(len(xy), dtype=bool)
    for p in peaks:
        near_any |= ((np.hypot(*(xy - p.pose[:2]).T) <= 0.5 + 1e-9)
                     & (np.abs((theta - p.pose[2] + np.pi) % (2 * np.pi) - np.pi) <= 0.3 + 1e-9))
    assert near_any.all()
    assert peaks[0].score == sums.max() / (prep.n * correlative.RASTER_MAX)


def test_peaks_hold_the_true_pose_where_a_mirror_image_scores_higher():
    # The TurtleBot3 world is nearly symmetric under a half turn: over every heading, the true pose and its mirror
    # image are both peaks, whichever wins; the caller's other evidence (a prior) picks.
    reference_points, current, truth = local_map_case(4)
    peaks = match_scans_grid_peaks(current, reference_points, initial_pose=(0.0, 0.0, 0.0),
                                   search_range=(2.0, 2.0, np.pi), resolution_m=0.05, max_peaks=8, min_ratio=0.5)
    errors = [pose_error(p.pose, truth) for p in peaks]
    assert any(t < 0.1 and r < 0.05 for t, r in errors), errors


def test_peaks_of_a_window_without_a_match_are_none_and_bad_parameters_raise(pairs):
    assert match_scans_grid_peaks(np.zeros((2, 2)), pairs[0].reference_points) == []
    for kwargs, message in (({"max_peaks": 0}, "max_peaks"), ({"min_ratio": 0.0}, "min_ratio"),
                            ({"separation": (0.0, 0.1)}, "separation")):
        with pytest.raises(ValueError, match=message):
            match_scans_grid_peaks(pairs[0].current_points, pairs[0].reference_points, **kwargs)
