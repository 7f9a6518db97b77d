"""``bagtools slam`` on real logs it was not tuned on (``../shared/data/radish``; skipped when absent).

Radish logs hold a scan about every metre of travel, 0.1 to 230 s apart: the
motion between scans is metres and tens of degrees, and the time step says
little of it. Scans only (the poses on their laser lines are a SLAM system's
answer), scored by the aligned APE against those corrected poses, as the
data's README says. Targets of issue #40: RMSE at most 0.2 m, max at most 0.75 m.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from bagtools.commands.slam import SlamOptions, SlamPipeline
from bagtools.trajectory.evaluate import ape_aligned
from bagtools.trajectory import Trajectory, read_tum
from bench.bench_slam_unseen import driven_backwards, restamped, revisit_consistency
from tests.conftest import REPO

RADISH_DIR = REPO.parent / "shared" / "data" / "radish"


def _log(name: str) -> Path:
    path = RADISH_DIR / f"{name}.log.gz"
    if not path.is_file():
        pytest.skip(f"Radish logs not available: {path} does not exist")
    return path


def _slam(source: Path, name: str) -> tuple[Trajectory, Trajectory]:
    """slam of ``source``, scans only, and log ``name``'s corrected poses, one per scan in logging order."""
    estimate = SlamPipeline(source, SlamOptions(use_odometry=False)).run().trajectory
    reference = read_tum(RADISH_DIR / f"{name}.reference.tum")
    assert len(estimate) == len(reference), f"{len(estimate)} poses for {len(reference)} scans"
    return estimate, reference


def _aligned_ape(source: Path, name: str) -> tuple[float, float]:
    """(RMSE, max) in m of slam's SE(2)-aligned positions (``_slam``) against the corrected poses, paired in
    logging order (whatever the stamps)."""
    estimate, reference = _slam(source, name)
    errors = ape_aligned(Trajectory(estimate.stamps_ns, reference.poses), estimate)
    return errors.rmse, errors.max


@pytest.mark.parametrize("name", ["seattle", "freiburg-101"])
def test_a_scan_per_metre_as_distributed(name: str) -> None:
    """Seattle's junction turns (a scan turned 90 degrees fits the crossing corridor too) and Freiburg 101's 20 s
    gaps: each map is consistent to the targets (0.050 and 0.065 m; 5.2 and 2.4 m before the motion model)."""
    rmse, worst = _aligned_ape(_log(name), name)
    assert rmse <= 0.2 and worst <= 0.75, (rmse, worst)


def test_waits_of_minutes_between_scans() -> None:
    """FHW: scans up to 230 s apart. A wait no longer predicts minutes of travel (it went 63 m the wrong way at a
    112 s step): 0.15 m RMSE, 0.51 m max (its beams 1 degree apart, as its PARAM says), against 21 m before."""
    rmse, worst = _aligned_ape(_log("fhw"), "fhw")
    assert rmse <= 0.2 and worst <= 0.75, (rmse, worst)


def test_steady_stamps_give_the_same_map(tmp_path: Path) -> None:
    """The same scans stamped 1 s apart (what a log with unusable stamps becomes): the motion model works per
    scan, and Seattle's loop still closes."""
    source = restamped(_log("seattle"), tmp_path / "seattle-steady.log", lambda k: f"{k:.6f}")
    rmse, worst = _aligned_ape(source, "seattle")
    assert rmse <= 0.2 and worst <= 0.75, (rmse, worst)


def test_a_corridor_loop_driven_backwards(tmp_path: Path) -> None:
    """Seattle's scans in reverse order, each gap kept: the same corridors on another route. A scan at a crossing
    fits turned by 90 degrees, and a corridor's doors repeat a metre apart; the step that chose the look-alike was
    kept until the next scan judged both contenders (6.9 m RMSE before, 0.064 m with it)."""
    source, reference = driven_backwards(_log("seattle"), RADISH_DIR / "seattle.reference.tum",
                                         tmp_path / "seattle-backwards.log")
    result = SlamPipeline(source, SlamOptions(use_odometry=False)).run()
    backwards = read_tum(reference)
    errors = ape_aligned(Trajectory(result.trajectory.stamps_ns, backwards.poses), result.trajectory)
    assert errors.rmse <= 0.2 and errors.max <= 0.75, (errors.rmse, errors.max)
    assert result.summary["front_end"]["revised_by_the_next_scan"] >= 1, result.summary["front_end"]


def test_a_large_hall_is_not_yet_to_target() -> None:
    """Edmonton: a convention centre with few revisits (63 of 340 scans lie within 2 m of an earlier pass). Its
    laser sees to 51 m (a PARAM said 10 m, and scans held a dozen returns). 0.35-0.60 m as distributed, 0.40-0.50 m
    with steady stamps, over the sessions (5.1 and 7.8 m before the motion model): the map bends smoothly away from
    the reference between revisits (issue #40 open). Where the robot came back, the scans agree with slam's map as
    well as with the reference's (bench ``revisit_consistency``: 0.144 against 0.146 m; a 2-degree bend of the
    reference, 0.2 m of aligned APE, costs it 0.010 m there): the bend is where no scan sees both passes. Bounds
    what holds."""
    estimate, reference = _slam(_log("edmonton"), "edmonton")
    errors = ape_aligned(Trajectory(estimate.stamps_ns, reference.poses), estimate)
    assert errors.rmse <= 0.7 and errors.max <= 2.0, (errors.rmse, errors.max)
    agree = revisit_consistency(_log("edmonton"), {"slam": estimate.poses, "reference": reference.poses},
                                RADISH_DIR / "edmonton.reference.tum")
    assert agree["slam"] <= agree["reference"] + 0.002, agree
