"""One meaning for a map's cell size (#42): --cell-size (m) and --cells-per-metre in grid and slam alike; the old
--resolution (cells per metre in grid, metres in slam) still runs the lab's commands, with a one-line note."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tests.cli.test_data_loss import run
from tests.conftest import FIXTURES

BAG = FIXTURES / "sim_lap_cloud_20s"


def _cell(out: Path) -> float:
    return json.loads((out / "summary.json").read_text())["grid"]["cell_size_m"]


@pytest.mark.parametrize("args, note", [
    (["--cell-size", "0.1"], False),
    (["--cells-per-metre", "10"], False),
    (["--resolution", "10"], True),  # grid's old spelling: cells per metre
])
def test_grid_cell_size_spellings(args: list[str], note: bool, tmp_path: Path, capsys) -> None:
    code, _, err = run(["grid", str(BAG), "--out", str(tmp_path / "g"), "--no-mcap", *args], capsys)
    assert code == 0, err
    assert _cell(tmp_path / "g") == pytest.approx(0.1)
    notes = [line for line in err.splitlines() if line.startswith("bagtools: note:")]
    assert notes == (["bagtools: note: --resolution 10 read as cells per metre (MATLAB's): a cell of 0.1 m; "
                      "--cell-size 0.1 says so in every command"] if note else [])


def test_slam_reads_the_old_resolution_as_metres_and_cell_size_alike(tmp_path: Path, capsys) -> None:
    for args in (["--resolution", "0.1"], ["--cell-size", "0.1"], ["--cells-per-metre", "10"]):
        out = tmp_path / args[0].strip("-")
        code, _, err = run(["slam", str(BAG), "--out", str(out), "--no-mcap", *args], capsys)
        assert code == 0, err
        assert json.loads((out / "summary.json").read_text())["options"]["resolution_m"] == pytest.approx(0.1)
        assert ("read as metres per cell (nav2's)" in err) == (args[0] == "--resolution")


@pytest.mark.parametrize("command", ["grid", "slam"])
def test_two_cell_sizes_are_a_usage_error_that_blames_no_file(command: str, tmp_path: Path, capsys) -> None:
    code, _, err = run([command, str(BAG), "--out", str(tmp_path / "o"), "--cell-size", "0.1", "--resolution", "10"],
                       capsys)
    assert code == 2 and "give one of --cell-size and --resolution" in err and str(BAG) not in err
    assert not (tmp_path / "o").exists()


def test_slam_refuses_grids_meaning_of_resolution(tmp_path: Path, capsys) -> None:
    """``slam --resolution 20`` (grid's cells per metre) would be 20 m cells: refused, saying metres."""
    code, _, err = run(["slam", str(BAG), "--out", str(tmp_path / "o"), "--resolution", "20"], capsys)
    assert code == 2 and "--resolution must be a cell side between 0.001 and 10 metres, got 20" in err
