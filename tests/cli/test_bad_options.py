"""Option values that are not numbers a run can use, or that would size an allocation past the memory budget,
are refused in one line naming the input, with exit status 2 and nothing written."""

from __future__ import annotations

from pathlib import Path

import pytest

from bagtools.cli import main
from bagtools.limits import memory_budget_bytes
from tests.conftest import FIXTURES

BAG = str(FIXTURES / "sim_lap_cloud_20s")


@pytest.mark.parametrize("argv, expected", [
    (["map-cloud", BAG, "--out", "{out}", "--voxel", "1e-9"], "--voxel must be a number of metres of at least"),
    (["map-cloud", BAG, "--out", "{out}", "--voxel", "nan"], "--voxel must be"),
    (["map-cloud", BAG, "--out", "{out}", "--voxel", "inf"], "--voxel must be"),
    (["map-cloud", BAG, "--out", "{out}", "--seed", "-5"], "--seed must be a non-negative integer"),
    (["ndt-odom", BAG, "--out", "{out}", "--cell-size", "1e-4"], "over the budget of"),
    (["tf", "echo", BAG, "odom", "base_footprint", "--rate", "1e9"], "time steps at 1e+09 Hz"),
    (["tf", "point", BAG, "--out", "{out}", "--point", "1", "0", "0", "--frame", "map", "--rate", "1e7"], "over the budget"),
    (["tf", "point", BAG, "--out", "{out}", "--point", "nan", "0", "0", "--frame", "map"], "--point must be three finite"),
    (["grid", BAG, "--out", "{out}", "--resolution", "1e-9"], "--resolution must be between"),
    (["simulate", "{out}", "--seed", "-5"], "--seed must be >= 0"),
    (["tf", "echo", BAG, "odom", "base_footprint", "--rate", "abc"], "invalid value for '--rate'"),
    (["grid", BAG, "--out", "{out}", "--poses", "nope.tum"], "nope.tum"),
    (["map-cloud", BAG, "--out", "{out}", "--stamp", "never"], "invalid value for '--stamp'"),
    (["ndt-odom", BAG, "--out", "{out}", "--scan-frame-offset", "1e308,1e308,0"], "within 100 m of the base"),
    (["grid", BAG, "--out", "{out}", "--scan-frame-offset", "0,nan,0"], "X and Y finite"),
    (["ndt-odom", BAG, "--out", "{out}", "--scan-frame-offset", "0,0,inf"], "YAW finite"),
    (["slam", BAG, "--out", "{out}", "--scan-frame-offset", "1,2"], "expected X,Y,YAW"),
])
def test_refused_in_one_line(argv: list[str], expected: str, tmp_path: Path, capsys) -> None:
    out = tmp_path / "out"
    with pytest.raises(SystemExit) as exit_info:
        main([a.replace("{out}", str(out)) for a in argv])
    err = capsys.readouterr().err
    assert exit_info.value.code == 2, err
    assert err.count("\n") == 1 and err.startswith("bagtools: ") and expected in err, err
    assert "Traceback" not in err
    assert not out.exists()
    name = str(out) if argv[0] == "simulate" else BAG
    assert err.startswith(f"bagtools: {name}") or "nope.tum" in err


def test_unknown_command_is_one_line(capsys) -> None:
    with pytest.raises(SystemExit) as exit_info:
        main(["mapp", BAG])
    err = capsys.readouterr().err
    assert exit_info.value.code == 2 and err.count("\n") == 1 and "no such command 'mapp'" in err


def test_memory_budget_from_environment(monkeypatch) -> None:
    monkeypatch.setenv("BAGTOOLS_MEMORY_BUDGET", "2G")
    assert memory_budget_bytes() == 2 << 30
    monkeypatch.setenv("BAGTOOLS_MEMORY_BUDGET", "500m")
    assert memory_budget_bytes() == 500 << 20
    monkeypatch.delenv("BAGTOOLS_MEMORY_BUDGET")
    assert memory_budget_bytes() >= 1 << 30


@pytest.mark.parametrize("argv", [
    ["grid", BAG, "--out", "{out}", "--resolution", "1000"],
    ["slam", BAG, "--out", "{out}", "--resolution", "0.001"],
])
def test_a_grid_past_the_memory_budget_is_refused(argv: list[str], tmp_path: Path, capsys, monkeypatch) -> None:
    """1 mm cells over the TurtleBot3 world: 90 M cells, 3.6 GB; both ran to 2.5 GB under a 100 MB budget."""
    monkeypatch.setenv("BAGTOOLS_MEMORY_BUDGET", "100M")
    out = tmp_path / "out"
    with pytest.raises(SystemExit) as exit_info:
        main([a.replace("{out}", str(out)) for a in argv])
    err = capsys.readouterr().err
    assert exit_info.value.code == 2 and err.count("\n") == 1, err
    assert "cells at 1000 cells/m would need 3.6 GB of memory, over the budget of 104.9 MB" in err
    assert not out.exists()


def test_a_scan_of_millions_of_beams_is_inserted_in_parts() -> None:
    """One scan of 2 million beams crosses some 80 million cells: traversed in parts, its peak stays a few hundred
    MB (a 20-million-beam scan reached 6 GB under a 1 GB budget), and a part's cells are as one insertion's."""
    import tracemalloc

    import numpy as np

    from bagtools.grid import OccupancyGrid
    from bagtools.grid.occupancy import RAY_CELLS_PER_PART

    grid = OccupancyGrid(10.0, 10.0, 20.0, np.array([-5.0, -5.0]))
    n = 2_000_000
    angles = np.linspace(-np.pi, np.pi, n, endpoint=False)
    tracemalloc.start()
    grid.insert_ray(np.zeros(3), np.full(n, 2.0), angles, 3.5)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    assert n * 2.0 * 20.0 > 10 * RAY_CELLS_PER_PART and peak < 1.0e9
    small = OccupancyGrid(10.0, 10.0, 20.0, np.array([-5.0, -5.0]))
    small.insert_ray(np.zeros(3), np.full(3600, 2.0), np.linspace(-np.pi, np.pi, 3600, endpoint=False), 3.5)
    assert np.array_equal(grid.occupancy_matrix() > 0.5, small.occupancy_matrix() > 0.5)


@pytest.mark.parametrize("argv, expected", [
    (["slam", "a.clf", "b.clf", "--out", "x"], "bagtools: got unexpected extra argument (b.clf) (see 'bagtools slam --help')"),
    (["slam", "a.clf"], "bagtools: missing option '--out' (see 'bagtools slam --help')"),
])
def test_a_wrong_command_line_blames_no_file(argv: list[str], expected: str, capsys) -> None:
    """The command line is wrong as a whole: a.clf is not at fault (it was named as the culprit)."""
    with pytest.raises(SystemExit) as exit_info:
        main(argv)
    assert exit_info.value.code == 2 and capsys.readouterr().err == expected + "\n"


@pytest.mark.parametrize("argv, expected", [
    (["grid", BAG, "--out", "{out}", "--frame", ""], "--frame must be a tf frame id"),
    (["ndt-odom", BAG, "--out", "{out}", "--max-speed", "1e9"], "--max-speed must be a positive number no robot exceeds"),
    (["ndt-odom", BAG, "--out", "{out}", "--max-turn-rate", "1e9"], "--max-turn-rate must be a positive number"),
    (["batch", "info", BAG, "--out", "{out}", "--workers", "99999999999999999999"], "invalid value for '--workers'"),
])
def test_options_no_run_can_mean_are_refused(argv: list[str], expected: str, tmp_path: Path, capsys) -> None:
    """They were taken as given: --frame '' ran as map, a 1e9 m/s robot, a batch of 1e20 workers exited 0."""
    out = tmp_path / "out"
    with pytest.raises(SystemExit) as exit_info:
        main([a.replace("{out}", str(out)) for a in argv])
    err = capsys.readouterr().err
    assert exit_info.value.code == 2 and err.count("\n") == 1 and expected in err, err
    assert not out.exists()


def test_an_initial_pose_off_any_map_is_refused(tmp_path: Path, capsys) -> None:
    """1e308 leaked numpy RuntimeWarnings (overflow) to stderr before any error."""
    with pytest.raises(SystemExit) as exit_info:
        main(["localize", BAG, "--map", str(tmp_path / "map.yaml"), "--out", str(tmp_path / "out"),
              "--initial-pose", "1e308,0,0"])
    err = capsys.readouterr().err
    assert exit_info.value.code == 2 and err.count("\n") == 1 and "within 1e+07 m of the map's origin" in err, err
    assert "Warning" not in err
