"""Atomic outputs: nothing half-written, nothing overwritten without force."""

from __future__ import annotations

from pathlib import Path

import pytest

from bagtools.errors import BagtoolsError, OutputExistsError
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


def test_own_directory_replaced_whole_with_force(tmp_path: Path) -> None:
    target = tmp_path / "bag"
    target.mkdir()
    (target / "old.mcap").write_bytes(b"old")
    with atomic_path(target, force=True, is_own_output=lambda p: True) as tmp:
        tmp.mkdir()
        (tmp / "new.mcap").write_bytes(b"new")
    assert [p.name for p in target.iterdir()] == ["new.mcap"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bag"]


def test_force_never_replaces_a_directory_that_is_not_the_commands_output(tmp_path: Path) -> None:
    target = tmp_path / "photos"
    target.mkdir()
    (target / "holiday.jpg").write_bytes(b"precious")
    for own in (None, lambda p: False):
        with pytest.raises(OutputExistsError, match="did not write"):
            with atomic_path(target, force=True, is_own_output=own) as tmp:
                tmp.write_text("csv")
        with pytest.raises(OutputExistsError, match="did not write"):
            write_text_atomic(target, "a,b\n", force=True)
    assert [p.name for p in target.iterdir()] == ["holiday.jpg"]
    assert (target / "holiday.jpg").read_bytes() == b"precious"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["photos"]


def test_output_dir_publishes_all_or_nothing(tmp_path: Path) -> None:
    out = tmp_path / "out"
    with pytest.raises(KeyboardInterrupt):
        with OutputDir(out, ["map.pgm", "map.yaml"]) as staged:
            (staged / "map.pgm").write_bytes(b"P5")
            raise KeyboardInterrupt
    assert not out.exists()  # the run created it, and leaves the file system as it found it
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


def test_output_dir_refuses_a_named_output_that_is_a_directory(tmp_path: Path) -> None:
    out = tmp_path / "out"
    (out / "map.png").mkdir(parents=True)
    (out / "map.png" / "keep.txt").write_text("mine")
    with pytest.raises(OutputExistsError, match="is a directory"):
        with OutputDir(out, ["map.png"], force=True) as staged:
            (staged / "map.png").write_bytes(b"png")
    assert (out / "map.png" / "keep.txt").read_text() == "mine"


def test_second_writer_is_refused_at_the_final_rename(tmp_path: Path) -> None:
    """Both runs pass the check at the start; the one that publishes second must not replace the first."""
    out = tmp_path / "out"
    first, second = OutputDir(out, ["a.txt"]), OutputDir(out, ["a.txt"])
    staged_first = first.__enter__()
    (staged_first / "a.txt").write_text("first")
    first.__exit__(None, None, None)
    with pytest.raises(OutputExistsError):
        with second as staged_second:
            (staged_second / "a.txt").write_text("second")
    assert (out / "a.txt").read_text() == "first"
    assert [p.name for p in out.iterdir()] == ["a.txt"]


def test_single_file_second_writer_refused_at_rename(tmp_path: Path) -> None:
    target = tmp_path / "tf.csv"
    with pytest.raises(OutputExistsError):
        with atomic_path(target) as tmp:
            tmp.write_text("late")
            target.write_text("another run finished first")
    assert target.read_text() == "another run finished first"
    assert [p.name for p in tmp_path.iterdir()] == ["tf.csv"]


def test_live_writer_is_refused_and_stale_staging_is_swept(tmp_path: Path) -> None:
    import subprocess
    import sys
    import textwrap

    out = tmp_path / "out"
    script = textwrap.dedent(f"""
        import sys, time
        from bagtools.outputs import OutputDir
        d = OutputDir({str(out)!r}, ["a.txt"])
        staged = d.__enter__()
        (staged / "a.txt").write_text("x" * 1000)
        print("staged", flush=True)
        time.sleep(60)
    """)
    proc = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline().strip() == "staged"
        with pytest.raises(BagtoolsError, match="another bagtools run is writing"):
            with OutputDir(out, ["b.txt"]):
                pass
    finally:
        proc.kill()  # SIGKILL: no clean-up runs in that process
        proc.wait()
    leftovers = [p.name for p in out.iterdir()]
    assert len(leftovers) == 1 and leftovers[0].startswith(".bagtools-")
    with OutputDir(out, ["b.txt"]) as staged:
        (staged / "b.txt").write_text("b")
    assert [p.name for p in out.iterdir()] == ["b.txt"]


def test_cannot_create_output_is_one_line_error(tmp_path: Path) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("x")
    with pytest.raises(BagtoolsError, match="cannot create the output directory"):
        with OutputDir(blocker / "sub", ["a.txt"]):
            pass
    with pytest.raises(BagtoolsError):
        write_text_atomic(blocker / "a.csv", "x")
    with pytest.raises(BagtoolsError):
        write_text_atomic("/proc/bagtools-test/a.csv", "x")


def test_staging_cut_short_by_sigkill_before_its_mark_is_swept_and_nothing_else(tmp_path: Path) -> None:
    """SIGKILL between making a staging directory and writing its mark leaves an unmarked directory: the next run
    removes it when its owner (the pid in its name) is gone and it holds nothing but part of the mark; one with
    anything else in it, or whose owner still runs, is left alone."""
    import os
    import subprocess
    import sys

    from bagtools.outputs import _LOCK_MARK, _LOCK_NAME, sweep_stale_staging

    gone = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    dead = int(gone.stdout)
    empty = tmp_path / f".sim.{dead}.aaaa.tmp"
    partial = tmp_path / f".sim.{dead}.bbbb.tmp"
    holding = tmp_path / f".sim.{dead}.cccc.tmp"
    running = tmp_path / f".sim.{os.getpid()}.dddd.tmp"
    for d in (empty, partial, holding, running):
        d.mkdir()
    (partial / _LOCK_NAME).write_bytes(_LOCK_MARK[:10])
    (holding / "user.txt").write_text("not ours to remove")
    assert sweep_stale_staging(tmp_path, ".sim.") == []
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([holding.name, running.name])
