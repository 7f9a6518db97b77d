"""``bagtools localize`` on real logs, scored against their references (skipped when the data is absent).

The targets' loose asserts (bench/bench_localize.py holds the rows on whole logs):

- the same log: a log mapped by ``bagtools slam`` (its defaults), then its scans localized in that map with no
  odometry and no initial pose, no worse than slam's own trajectory on the log's relations;
- the reverse: a log's first half mapped by slam, its second half localized in that map, scans only, scored on
  the relations inside the second half;
- CSAIL: one bag localized in the slam map of the other, against the log's reference poses.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from bagtools.grid import write_nav2_map
from bagtools.commands.localize import LocalizeOptions, LocalizePipeline
from bagtools.commands.slam import SlamOptions, SlamPipeline
from bagtools.trajectory import read_relations
from bagtools.trajectory.relations import relation_errors
from tests.conftest import REPO, ros1_scan_slice

BENCHMARK_DIR = REPO.parent / "shared" / "data" / "benchmark"
SCANS_ONLY = LocalizeOptions(use_odometry=False)


def _log(name: str) -> tuple[Path, Path]:
    bag, relations = BENCHMARK_DIR / f"{name}.bag", BENCHMARK_DIR / f"{name}.relations"
    if not (bag.is_file() and relations.is_file()):
        pytest.skip(f"benchmark logs not available: {bag} or {relations} does not exist")
    return bag, relations


def _all_tracked(summary: dict) -> None:
    """Every scan placed, none lost, the first fix within the first scans."""
    assert summary["scans_localized"] == summary["scans"], summary["scans_by_state"]
    assert summary["lost"] == 0, summary["events"]
    assert summary["first_fix"] is not None and summary["first_fix"]["seconds_after_first_scan"] < 5.0


def test_intel_scans_only_in_its_own_slam_map_are_no_worse_than_slam(tmp_path: Path) -> None:
    """The Intel lab's first 2500 scans (485 s): slam (with the wheels) maps them; localize, from the scans alone
    and no initial pose, places every scan, and on the log's relations is no worse than slam's own trajectory (the
    whole log's bench row: 0.0162 m against slam's 0.0161 m)."""
    bag, relations = _log("intel")
    head = ros1_scan_slice(bag, tmp_path / "intel_head.bag", 0, 2500)
    slam = SlamPipeline(head, SlamOptions()).run()
    map_yaml = write_nav2_map(slam.grid, tmp_path / "map")
    result = LocalizePipeline(head, map_yaml, SCANS_ONLY).run()
    _all_tracked(result.summary)
    reference = read_relations(relations)
    ours, theirs = relation_errors(reference, result.trajectory), relation_errors(reference, slam.trajectory)
    assert ours["used"] > 300 and ours["used"] == theirs["used"]
    assert ours["trans_mean_m"] <= 1.05 * theirs["trans_mean_m"], (ours, theirs)
    assert ours["trans_max_m"] < 0.5, ours


def test_fr079_second_half_in_the_map_of_its_first_half(tmp_path: Path) -> None:
    """Freiburg 079 cut in two by its scans: slam maps the first half (scans 0-2466); the second (2467-4933)
    is localized in that map from the scans alone, with no initial pose. On the relations inside the second half
    it scores 0.0327 m (bench); slam of the whole log scores 0.0317 m there and slam of the second half's own scans
    0.0329 m. Asserted loosely: within 1.1x of the whole log's slam, no relation off by 0.3 m."""
    bag, relations = _log("fr079")
    first = ros1_scan_slice(bag, tmp_path / "fr079_first.bag", 0, 2467)
    second = ros1_scan_slice(bag, tmp_path / "fr079_second.bag", 2467, 4934)
    map_yaml = write_nav2_map(SlamPipeline(first, SlamOptions()).run().grid, tmp_path / "first_half")
    result = LocalizePipeline(second, map_yaml, SCANS_ONLY).run()
    _all_tracked(result.summary)
    inside = read_relations(relations).within(int(result.stamps_ns[0]), int(result.stamps_ns[-1]))
    error = relation_errors(inside, result.trajectory)
    assert error["used"] > 700
    assert error["trans_mean_m"] < 1.1 * 0.0317 and error["trans_max_m"] < 0.3, error


def test_csail_with_its_wheels_in_the_slam_map_of_its_scans(real_dir: Path, tmp_path: Path) -> None:
    """CSAIL (380 m, a scan every metre or so): slam maps the scans-only bag; the bag with wheel odometry is
    localized in that map with no initial pose. Every scan placed, within 0.1 m of the log's reference poses after
    alignment (GMapping's; slam's own figure is 0.08 m, the bench's localize 0.080 m)."""
    scans, odom = real_dir / "csail_scans", real_dir / "csail_odom"
    if not (scans.is_dir() and odom.is_dir()):
        pytest.skip(f"real bags not available: {scans}, {odom}")
    map_yaml = write_nav2_map(SlamPipeline(scans, SlamOptions()).run().grid, tmp_path / "map")
    summary = LocalizePipeline(odom, map_yaml).run().summary
    _all_tracked(summary)
    assert summary["odometry_used"]
    assert summary["ground_truth"]["ours"]["ape_aligned_m"]["rmse"] < 0.1, summary["ground_truth"]
