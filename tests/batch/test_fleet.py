"""The fleet table: stable columns and types whatever happened, CSV and Parquet agreeing, and the picture."""

from __future__ import annotations

import csv
from pathlib import Path

import pyarrow.parquet as pq
import pytest

from bagtools.batch.fleet import FLEET_FILES, fleet_csv, write_fleet
from bagtools.batch.jobs import JOBS
from bagtools.batch.plan import row_columns


def _rows(command: str, n: int, failed: set[int]) -> list[dict]:
    job = JOBS[command]
    rows = []
    for i in range(n):
        ok = i not in failed
        row = {"bag": f"robot{i}", "path": f"/data/robot{i}", "status": "ok" if ok else "failed",
               "error": "" if ok else f"/data/robot{i}: not a ROS bag", "duration_s": 1.5 + i,
               "messages": 1000 + i if ok else None}
        row.update({c.name: ((i + 1) if c.kind == "int" else 0.5 / (i + 1)) if ok else None for c in job.columns})
        rows.append(row)
    return rows


@pytest.mark.parametrize("command", sorted(JOBS))
def test_every_command_has_a_table_and_a_picture_even_when_every_bag_failed(command: str, tmp_path: Path) -> None:
    rows = _rows(command, 3, failed={0, 1, 2})
    written = write_fleet(tmp_path, rows, JOBS[command], title="all failed")
    assert [p.name for p in written] == FLEET_FILES
    table = pq.read_table(tmp_path / "fleet.parquet")
    assert table.column_names == row_columns(JOBS[command]) and table.num_rows == 3
    assert table.column("messages").null_count == 3
    assert (tmp_path / "fleet.png").stat().st_size > 1000


def test_csv_and_parquet_hold_the_same_rows(tmp_path: Path) -> None:
    job = JOBS["ndt-odom"]
    rows = _rows("ndt-odom", 70, failed={3, 40})  # more bags than the picture labels
    write_fleet(tmp_path, rows, job, title="ndt-odom")
    with (tmp_path / "fleet.csv").open() as f:
        from_csv = list(csv.DictReader(f))
    from_parquet = pq.read_table(tmp_path / "fleet.parquet").to_pylist()
    assert [r["bag"] for r in from_csv] == [r["bag"] for r in from_parquet] == [r["bag"] for r in rows]
    assert from_parquet[3]["ape_ndt_m"] is None and from_csv[3]["ape_ndt_m"] == ""
    assert from_parquet[5] == rows[5] and float(from_csv[5]["ape_ndt_m"]) == rows[5]["ape_ndt_m"]
    assert fleet_csv(rows[:1], row_columns(job)).splitlines()[0].startswith("bag,path,status,error,duration_s,messages,")


def test_the_table_is_replaced_by_the_next_run_and_nothing_else_is_touched(tmp_path: Path) -> None:
    (tmp_path / "notes.txt").write_text("mine")
    write_fleet(tmp_path, _rows("grid", 2, set()), JOBS["grid"], title="first")
    write_fleet(tmp_path, _rows("grid", 1, {0}), JOBS["grid"], title="second")
    assert pq.read_table(tmp_path / "fleet.parquet").column("status").to_pylist() == ["failed"]
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([*FLEET_FILES, "notes.txt"])
