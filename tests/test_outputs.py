"""Atomic outputs: nothing half-written, nothing overwritten without force."""

from __future__ import annotations

from pathlib import Path

import pytest

from bagtools.errors import OutputExistsError
from bagtools.outputs import OutputDir, atomic_path, write_text_atomic


def test_write_and_refuse_overwrite(tmp_path: Path) -> None:
    target = tmp_path / "a.txt"
    write_text_atomic(target, "one")
    with pytest.raises(OutputExistsError, match="use --force"):
        write_text_atomic(target, "two")
    assert target.read_text() == "one"
    write_text_atomic(target, "two", force=True)
    assert target.read_text() == "two"


def test_error_leaves_nothing(tmp_path: Path) -> None:
    target = tmp_path / "bag"
    with pytest.raises(RuntimeError):
        with atomic_path(target) as tmp:
            tmp.mkdir()
            (tmp / "half.mcap").write_bytes(b"x")
            raise RuntimeError("power cut")
    assert list(tmp_path.iterdir()) == []


def test_directory_replaced_whole_with_force(tmp_path: Path) -> None:
    target = tmp_path / "bag"
    target.mkdir()
    (target / "old.mcap").write_bytes(b"old")
    with atomic_path(target, force=True) as tmp:
        tmp.mkdir()
        (tmp / "new.mcap").write_bytes(b"new")
    assert [p.name for p in target.iterdir()] == ["new.mcap"]


def test_output_dir_publishes_all_or_nothing(tmp_path: Path) -> None:
    out = tmp_path / "out"
    with pytest.raises(KeyboardInterrupt):
        with OutputDir(out, ["map.pgm", "map.yaml"]) as staged:
            (staged / "map.pgm").write_bytes(b"P5")
            raise KeyboardInterrupt
    assert list(out.iterdir()) == []
    with OutputDir(out, ["map.pgm", "map.yaml"]) as staged:
        (staged / "map.pgm").write_bytes(b"P5")
        (staged / "map.yaml").write_text("image: map.pgm\n")
    assert sorted(p.name for p in out.iterdir()) == ["map.pgm", "map.yaml"]
    with pytest.raises(OutputExistsError):
        with OutputDir(out, ["map.yaml"]):
            pass
    (out / "other.txt").write_text("kept")
    with OutputDir(out, ["map.yaml"], force=True) as staged:
        (staged / "map.yaml").write_text("image: new.pgm\n")
    assert (out / "map.yaml").read_text() == "image: new.pgm\n" and (out / "other.txt").read_text() == "kept"


def test_output_dir_removes_stale_named_outputs_with_force(tmp_path: Path) -> None:
    out = tmp_path / "out"
    with OutputDir(out, ["trajectory.tum", "ground_truth.tum"]) as staged:
        (staged / "trajectory.tum").write_text("a")
        (staged / "ground_truth.tum").write_text("truth of another bag")
    with OutputDir(out, ["trajectory.tum", "ground_truth.tum"], force=True) as staged:
        (staged / "trajectory.tum").write_text("b")
    assert sorted(p.name for p in out.iterdir()) == ["trajectory.tum"]
