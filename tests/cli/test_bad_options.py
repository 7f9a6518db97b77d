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
