"""``bagtools slam`` as a command: help, refusals before any work, one-line errors with exit status 2."""

from __future__ import annotations

import contextlib
import io
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from bagtools.cli import main
from tests.conftest import FIXTURES


def _run(*args: str) -> subprocess.CompletedProcess:
    """``bagtools ARGS`` in this process (the CLI's own entry point, exit status and both streams)."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            main(list(args))
            code = 0
        except SystemExit as exc:
            code = int(exc.code or 0)
    return subprocess.CompletedProcess(["bagtools", *args], code, out.getvalue(), err.getvalue())


def test_help_has_an_example_and_says_the_resolution_unit() -> None:
    out = subprocess.run([sys.executable, "-m", "bagtools", "slam", "--help"], capture_output=True, text=True)
    assert out.returncode == 0 and "Example:" in out.stdout and "bagtools slam out/sim --out out/slam" in out.stdout
    assert "METRES" in out.stdout and "--no-odometry" in out.stdout and "--loop-search-radius" in out.stdout


@pytest.mark.parametrize("args,message", [
    (["--topic", "/laser"], "no topic '/laser' in the bag (LaserScan topics: /scan"),
    (["--resolution", "0"], "--resolution must be a cell side between"),
    (["--loop-search-radius", "nan"], "--loop-search-radius must be a positive number of metres"),
])
def test_bad_input_is_one_line(tmp_path: Path, args: list[str], message: str) -> None:
    bag = FIXTURES / "sim_random_nocloud_20s"
    done = _run("slam", str(bag), "--out", str(tmp_path / "out"), *args)
    assert done.returncode == 2 and done.stderr.count("\n") == 1, done.stderr
    assert done.stderr.startswith(f"bagtools: {bag}: ") and message in done.stderr
    assert not (tmp_path / "out").exists()


def test_missing_bag_and_existing_outputs(tmp_path: Path) -> None:
    done = _run("slam", str(tmp_path / "nothing.mcap"), "--out", str(tmp_path / "out"))
    assert done.returncode == 2 and done.stderr.count("\n") == 1 and "nothing.mcap" in done.stderr
    out = tmp_path / "out"
    out.mkdir()
    (out / "map.pgm").write_text("mine")
    done = _run("slam", str(FIXTURES / "sim_random_nocloud_20s"), "--out", str(out))
    assert done.returncode == 2 and "already exists (use --force to overwrite)" in done.stderr
    assert (out / "map.pgm").read_text() == "mine"


def test_end_to_end_with_and_without_odometry(tmp_path: Path) -> None:
    bag = FIXTURES / "sim_random_nocloud_20s"
    out = tmp_path / "slam"
    done = _run("slam", str(bag), "--out", str(out))
    assert done.returncode == 0, done.stderr
    assert "scans," in done.stdout and "keyframes;" in done.stdout and "SLAM: APE" in done.stdout
    assert sorted(p.name for p in out.iterdir()) == sorted(
        ["trajectory.tum", "odometry.tum", "ground_truth.tum", "pose_graph.g2o", "map.pgm", "map.yaml", "map.png",
         "summary.json", "results.mcap"])
    summary = json.loads((out / "summary.json").read_text())
    assert summary["front_end"]["odometry_used"] and summary["errors_slam"]["ape_aligned_m"]["rmse"] < 0.05
    forced = _run("slam", str(bag), "--out", str(out), "--no-odometry", "--no-loop-closure", "--max-range", "3",
                  "--resolution", "0.1", "--force")
    assert forced.returncode == 0, forced.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert not summary["front_end"]["odometry_used"] and summary["loop_closure"]["candidates"] == 0
    assert summary["map"]["grid"]["cell_size_m"] == 0.1 and summary["map"]["max_range_m"] == [3.0]
    assert (out / "trajectory.tum").read_text() == (out / "odometry.tum").read_text()


def test_relations_score_both_trajectories(tmp_path: Path) -> None:
    """--relations (Kuemmerle et al.'s metric): relations from the bag's true poses, consecutive and 20 scans apart."""
    from bagtools.trajectory import Trajectory, read_tum, relations_from_trajectory, relations_text

    bag = FIXTURES / "sim_random_nocloud_20s"
    first = _run("slam", str(bag), "--out", str(tmp_path / "first"), "--no-mcap")
    assert first.returncode == 0, first.stderr
    truth = read_tum(tmp_path / "first" / "ground_truth.tum")
    at_scans = np.isin(truth.stamps_ns, read_tum(tmp_path / "first" / "trajectory.tum").stamps_ns)
    truth = Trajectory(truth.stamps_ns[at_scans], truth.poses[at_scans])
    n = len(truth)
    assert n > 90
    pairs = [(i, i + 1) for i in range(n - 1)] + [(i, i + 20) for i in range(0, n - 20, 5)]
    relations = tmp_path / "sim.relations"
    relations.write_text(relations_text(relations_from_trajectory(truth, np.array(pairs))) + "1.0 2.0 0 0 0 0 0 0\n")
    done = _run("slam", str(bag), "--out", str(tmp_path / "scored"), "--no-mcap", "--relations", str(relations))
    assert done.returncode == 0, done.stderr
    assert "SLAM: relations error" in done.stdout and "laser odometry: relations error" in done.stdout
    assert done.stdout.count("(1 without a pose at both stamps)") == 2, done.stdout  # the 1.0 -> 2.0 line
    scored = json.loads((tmp_path / "scored" / "summary.json").read_text())["relations"]
    assert scored["file"] == str(relations)
    for name in ("slam", "front_end"):
        assert scored[name]["relations"] == len(pairs) + 1 and scored[name]["used"] == len(pairs)
        assert scored[name]["missing"] == 1  # the last line's stamps are not in the bag
        assert scored[name]["trans_mean_m"] < 0.02 and scored[name]["rot_mean_deg"] < 0.5, scored[name]


def test_a_bad_relations_file_is_refused_before_the_work(tmp_path: Path) -> None:
    bad = tmp_path / "bad.relations"
    bad.write_text("1.0 2.0 0.1\n")
    for path in (bad, tmp_path / "missing.relations"):
        done = _run("slam", str(FIXTURES / "sim_random_nocloud_20s"), "--out", str(tmp_path / "out"),
                    "--relations", str(path))
        assert done.returncode == 2 and done.stderr.count("\n") == 1, done.stderr
        assert done.stderr.startswith(f"bagtools: {path}: ") and not (tmp_path / "out").exists()


def test_uncertain_front_end_steps_are_said_on_the_summary_line(tmp_path: Path, monkeypatch) -> None:
    """Loops rejected are counted by reason on the summary line; steps the front end left uncertain (ambiguous:
    another place matched almost as well) are said there too, not only past a 3 % warning threshold, and so are
    contested steps the scan after them decided otherwise."""
    from bagtools.commands.slam import SlamPipeline

    run = SlamPipeline.run

    def with_uncertain(self):
        result = run(self)
        result.summary["front_end"]["ambiguous"] = 2
        result.summary["front_end"]["revised_by_the_next_scan"] = 3
        return result

    monkeypatch.setattr(SlamPipeline, "run", with_uncertain)
    done = _run("slam", str(FIXTURES / "sim_random_nocloud_20s"), "--out", str(tmp_path / "slam"), "--no-mcap")
    assert done.returncode == 0, done.stderr
    assert ("; 2 front-end step(s) left uncertain (another place matched almost as well); 3 contested step(s) "
            "changed by the scan after them") in done.stdout
