"""Each bag's job, in this process: the same files as the single command, one row, the error boundary, the marker."""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest

from bagtools.batch.jobs import JOBS
from bagtools.batch.task import (
    FAILED, MARKER, OK, SKIPPED, BagTask, ForeignOutputError, check_owner, completed_row, read_marker, run_task,
)
from bagtools.cli import COMMANDS, cli, main
from bagtools.commands.grid import GRID_MAP_FILES
from tests.batch.conftest import Fleet
from tests.conftest import FIXTURES

SIM_BAG = FIXTURES / "sim_lap_cloud_20s"


class _Recording(Mapping):
    """A parameter mapping that remembers which keys were read."""

    def __init__(self, data: dict) -> None:
        self.data, self.read = data, set()

    def __getitem__(self, key: str) -> Any:
        self.read.add(key)
        return self.data[key]

    def __iter__(self):
        return iter(self.data)

    def __len__(self) -> int:
        return len(self.data)


def _params(command: str, args: list[str] = ()) -> dict:
    """The command's parameters as its own click command parses them (without bag, out_dir, force)."""
    import click

    sub = cli.get_command(click.Context(cli), command)
    argv = ["BAG", *(["--out", "OUT"] if any(p.name == "out_dir" for p in sub.params) else []), *args]
    with sub.make_context(command, argv) as ctx:
        params = dict(ctx.params)
    for name in ("bag", "out_dir", "force"):
        params.pop(name, None)
    return params


def _task(command: str, bag: Path, out_dir: Path, args: list[str] = (), force: bool = False, name: str = "bag") -> BagTask:
    params = _params(command, list(args))
    settings = json.loads(json.dumps({k: v for k, v in params.items() if k not in JOBS[command].ignored}, sort_keys=True))
    return BagTask(command, str(bag), name, str(out_dir), JOBS[command].options(params), settings, force)


def _cli(argv: list[str], capsys) -> tuple[int, str, str]:
    with pytest.raises(SystemExit) as exit_info:
        main(argv)
    out = capsys.readouterr()
    return exit_info.value.code, out.out, out.err


def _without_timing(value: Any) -> Any:
    """A summary without its wall-clock figures (the only part two runs may differ in)."""
    if isinstance(value, dict):
        return {k: _without_timing(v) for k, v in value.items() if not any(w in k for w in ("elapsed", "time", "timing"))}
    return value


def test_every_job_is_a_registered_command() -> None:
    assert set(JOBS) <= set(COMMANDS)


def _required_args(command: str, tmp_path: Path) -> list[str]:
    """The options a command cannot run without (localize's map: a small nav2 map written here)."""
    if command != "localize":
        return []
    image = bytearray(b"\xfe" * 100)
    image[10:20] = b"\x00" * 10
    (tmp_path / "m.pgm").write_bytes(b"P5\n10 10\n255\n" + bytes(image))
    (tmp_path / "m.yaml").write_text("image: m.pgm\nresolution: 0.05\norigin: [0, 0, 0]\nnegate: 0\n"
                                     "occupied_thresh: 0.65\nfree_thresh: 0.196\n")
    return ["--map", str(tmp_path / "m.yaml")]


@pytest.mark.parametrize("command", sorted(JOBS))
def test_a_job_uses_every_option_of_its_command(command: str, tmp_path: Path) -> None:
    """A new option of the command that the batch job would silently drop fails here."""
    params = _Recording(_params(command, _required_args(command, tmp_path)))
    JOBS[command].options(params)
    assert set(params.data) - params.read - JOBS[command].ignored == set(), "options the batch job drops"
    assert not params.read & JOBS[command].ignored


class _Built(Exception):
    """Raised by a stand-in pipeline with the options the command built."""


@pytest.mark.parametrize("command, pipeline, args", [
    ("slam", "bagtools.commands.slam.SlamPipeline", ["--no-odometry", "--loop-min-score", "0.6", "--cell-size", "0.1"]),
    ("ndt-odom", "bagtools.commands.ndt_odom.NdtOdomPipeline", ["--reference", "previous", "--max-speed", "0.7", "--holonomic"]),
    ("grid", "bagtools.commands.grid.GridMapPipeline", ["--resolution", "10", "--max-range", "8"]),
    ("map-cloud", "bagtools.commands.map_cloud.CloudMapPipeline", ["--voxel", "0.05", "--seed", "3"]),
    ("localize", "bagtools.commands.localize.LocalizePipeline", ["--no-smoothing", "--initial-pose", "1,2,0.5"]),
])
def test_the_command_and_its_job_build_the_same_options(command: str, pipeline: str, args: list[str], tmp_path: Path,
                                                         monkeypatch) -> None:
    """One description of each command: what ``bagtools COMMAND`` runs with equals what its batch job runs with,
    defaults and given options alike."""
    module, name = pipeline.rsplit(".", 1)
    built = []

    def stand_in(bag, *rest, **kwargs):
        built.append(next(a for a in (*rest, *kwargs.values()) if hasattr(a, "__dataclass_fields__")))
        raise _Built

    monkeypatch.setattr(f"{module}.{name}", stand_in)
    required = _required_args(command, tmp_path)
    with pytest.raises(_Built):
        cli.main([command, str(SIM_BAG), "--out", str(tmp_path / "out"), *required, *args], standalone_mode=False)
    job = JOBS[command].options(_params(command, [*required, *args])).options
    assert built == [job[1] if command == "localize" else job]


@pytest.mark.parametrize("command, options, differs", [
    ("slam", "bagtools.commands.slam.SlamOptions", {"keep_scans": True}),  # results.mcap unless --no-mcap
    ("ndt-odom", "bagtools.commands.ndt_odom.NdtOdomOptions", {}),
    ("grid", "bagtools.commands.grid.GridMapOptions", {}),
    ("map-cloud", "bagtools.commands.map_cloud.CloudMapOptions", {}),
    ("localize", "bagtools.commands.localize.LocalizeOptions", {}),
])
def test_a_command_given_no_options_runs_with_its_options_defaults(command: str, options: str, differs: dict,
                                                                  tmp_path: Path) -> None:
    """The click options restate no default differently from the command's options dataclass (where the defaults
    live): a default changed in one place only fails here."""
    import dataclasses
    import importlib

    module, name = options.rsplit(".", 1)
    cls = getattr(importlib.import_module(module), name)
    built = cls.from_params(_params(command, _required_args(command, tmp_path)))
    assert built == dataclasses.replace(cls(), **differs)


@pytest.mark.parametrize("command, args", [
    ("grid", ["--resolution", "10"]),
    ("ndt-odom", ["--reference", "previous"]),
    ("map-cloud", ["--voxel", "0.05", "--sample", "0.05"]),
    ("slam", ["--no-mcap"]),
])
def test_a_job_writes_exactly_what_the_command_writes(command: str, args: list[str], fleet: Fleet, tmp_path: Path,
                                                      capsys) -> None:
    bag = SIM_BAG if command == "map-cloud" else fleet.good[0]  # the only one with depth clouds, else a short one
    code, _, err = _cli([command, str(bag), "--out", str(tmp_path / "single"), *args], capsys)
    assert code == 0, err
    row = run_task(_task(command, bag, tmp_path / "batch", args, name="sim"))
    assert row["status"] == OK and row["error"] == "", row
    single, batch = tmp_path / "single", tmp_path / "batch" / "sim"
    names = sorted(p.name for p in single.iterdir())
    assert sorted(p.name for p in batch.iterdir()) == sorted([*names, MARKER])
    for name in names:
        if name == "summary.json":
            assert _without_timing(json.loads((batch / name).read_text())) == \
                _without_timing(json.loads((single / name).read_text()))
        elif not name.endswith(".png"):
            assert (batch / name).read_bytes() == (single / name).read_bytes(), name
    summary = json.loads((batch / "summary.json").read_text())
    for column in JOBS[command].columns:
        assert row[column.name] == column.value(summary)
    assert row["messages"] > 0 and row["duration_s"] > 0


def test_info_writes_what_info_json_prints(tmp_path: Path, capsys) -> None:
    code, out, _ = _cli(["info", str(SIM_BAG), "--json"], capsys)
    assert code == 0
    row = run_task(_task("info", SIM_BAG, tmp_path, ["--json"], name="sim"))
    assert (tmp_path / "sim" / "info.json").read_text() == out
    info = json.loads(out)
    assert row["status"] == OK and row["messages"] == info["message_count"]
    assert row["bag_duration_s"] == info["duration_s"] and row["topics"] == len(info["topics"])


def test_a_corrupt_bag_is_a_failed_row_with_the_commands_one_line(fleet: Fleet, tmp_path: Path, capsys) -> None:
    code, _, err = _cli(["grid", str(fleet.corrupt), "--out", str(tmp_path / "single")], capsys)
    assert code == 2
    row = run_task(_task("grid", fleet.corrupt, tmp_path / "batch"))
    assert row["status"] == FAILED and f"bagtools: {row['error']}" == err.strip()
    assert "truncated MCAP" in row["error"] and row["messages"] is None
    assert all(row[c.name] is None for c in JOBS["grid"].columns)
    assert not (tmp_path / "batch").exists()


def test_a_bag_without_the_topic_says_so_and_writes_nothing(fleet: Fleet, tmp_path: Path) -> None:
    row = run_task(_task("ndt-odom", fleet.no_scan, tmp_path))
    assert row["status"] == FAILED and "no topic '/scan' in the bag" in row["error"]
    assert row["error"].startswith(str(fleet.no_scan)) and row["messages"] == 20
    assert not (tmp_path / "bag").exists()


def test_an_unexpected_exception_is_an_internal_error_row(fleet: Fleet, tmp_path: Path, monkeypatch) -> None:
    def broken(bag: str, out_dir: Path, options: Any, force: bool):
        raise ZeroDivisionError("division by zero\nin the middle")

    monkeypatch.setitem(JOBS, "grid", replace(JOBS["grid"], run=broken))
    row = run_task(_task("grid", fleet.good[0], tmp_path))
    assert row["status"] == FAILED and row["error"] == "internal error: ZeroDivisionError: division by zero in the middle"
    assert read_marker(tmp_path / "bag") is None


def test_the_marker_makes_a_rerun_skip_only_complete_matching_outputs(fleet: Fleet, tmp_path: Path) -> None:
    task = _task("grid", fleet.good[0], tmp_path)
    row = run_task(task)
    marker = read_marker(task.bag_dir)
    assert marker["bag"] == task.bag and marker["files"] == sorted(GRID_MAP_FILES)
    skipped = completed_row(task, marker)
    assert skipped == {**row, "status": SKIPPED}
    other_settings = _task("grid", fleet.good[0], tmp_path, ["--resolution", "10"])
    assert completed_row(other_settings, marker) is None
    (task.bag_dir / "map.png").unlink()
    assert completed_row(task, marker) is None
    other_bag = replace(task, bag=str(fleet.good[1]))
    with pytest.raises(ForeignOutputError, match="holds the outputs of another bag"):
        check_owner(other_bag, marker)


def test_outputs_without_a_marker_are_not_overwritten_without_force(fleet: Fleet, tmp_path: Path) -> None:
    task = _task("grid", fleet.good[0], tmp_path)
    assert run_task(task)["status"] == OK
    (task.bag_dir / MARKER).unlink()
    again = run_task(task)
    assert again["status"] == FAILED and "already exists (use --force to overwrite)" in again["error"]
    assert read_marker(task.bag_dir) is None
    assert run_task(replace(task, force=True))["status"] == OK and read_marker(task.bag_dir) is not None


def test_the_message_count_reads_the_summary_and_falls_back_to_the_reader(fleet: Fleet, tmp_path: Path) -> None:
    from bagtools.batch.task import message_count
    from bagtools.errors import BagError
    from bagtools.io import open_bag

    bag = fleet.good[2]
    with open_bag(bag) as reader:
        full = reader.message_count
    assert message_count(str(bag)) == full
    storage = next(bag.glob("*.mcap"))
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(storage.read_bytes()[: storage.stat().st_size // 2])  # no summary: the reader recovers what it can
    with open_bag(cut) as reader:
        recovered = reader.message_count
    assert 0 < message_count(str(cut)) == recovered < full
    with pytest.raises(BagError, match="truncated MCAP"):
        message_count(str(fleet.corrupt))
