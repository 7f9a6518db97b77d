"""Round 2 of data loss: a user's recording is never touched.

--force replaces only what carries bagtools' mark, no output may be an input
(or lie inside one, or hold one), folders that merely look like staging are
never cleaned up, an interrupt or a failure leaves the file system as it was,
and a dangling symlink counts as an existing output.
"""

from __future__ import annotations

import os
import shutil
import signal
import time
from pathlib import Path

import pytest

from bagtools.errors import BagtoolsError
from bagtools.outputs import OWN_OUTPUT_MARK, OutputDir, _signals_held, atomic_path, write_text_atomic
from tests.cli.test_data_loss import run, snapshot
from tests.conftest import FIXTURES

BAG = FIXTURES / "sim_lap_cloud_20s"


@pytest.fixture
def recording(tmp_path: Path) -> Path:
    """A rosbag2 directory as `ros2 bag record` leaves it: metadata.yaml and .mcap files, no bagtools mark."""
    bag = tmp_path / "rosbag2_2026_11_28-10_00_00"
    shutil.copytree(BAG, bag)
    return bag


def test_simulate_force_never_deletes_a_recording_that_looks_like_its_bag(recording: Path, capsys) -> None:
    before = snapshot(recording.parent)
    code, _, err = run(["simulate", str(recording), "--duration", "1", "--no-cloud", "--force"], capsys)
    assert code == 2 and err.count("\n") == 1 and "did not write" in err, err
    assert snapshot(recording.parent) == before


def test_simulate_force_refuses_its_own_bag_once_the_user_added_a_file(tmp_path: Path, capsys) -> None:
    out = tmp_path / "sim"
    assert run(["simulate", str(out), "--duration", "1", "--no-cloud"], capsys)[0] == 0
    assert (out / OWN_OUTPUT_MARK).is_file()
    (out / "notes.txt").write_text("mine")
    before = snapshot(tmp_path)
    code, _, err = run(["simulate", str(out), "--duration", "1", "--no-cloud", "--force"], capsys)
    assert code == 2 and "did not write" in err and snapshot(tmp_path) == before


@pytest.mark.parametrize("argv", [
    ["tf", "echo", "{bag}", "odom", "base_footprint", "--csv", "{out}", "--force"],
    ["tf", "frames", "{bag}", "--dot", "{out}", "--force"],
    ["export", "{bag}", "/odom", "--out", "{out}", "--force"],
])
@pytest.mark.parametrize("where", ["the bag itself", "a file inside it", "a symlink to it"])
def test_a_file_output_that_is_the_input_is_refused_even_with_force(argv: list[str], where: str, recording: Path,
                                                                     capsys) -> None:
    mcap = next(recording.glob("*.mcap"))
    bag, out = {"the bag itself": (mcap, mcap), "a file inside it": (recording, recording / "tf.csv"),
                "a symlink to it": (mcap, recording.parent / "link.mcap")}[where]
    if where == "a symlink to it":
        out.symlink_to(mcap)
    if argv[0] == "export":
        out = out.with_suffix(".csv") if where == "a file inside it" else out
    before = snapshot(recording.parent)
    code, _, err = run([a.replace("{bag}", str(bag)).replace("{out}", str(out)) for a in argv], capsys)
    assert code == 2 and err.count("\n") == 1, err
    assert "is the input" in err or "lies inside the input" in err or "already exists" in err, err
    assert snapshot(recording.parent) == before


@pytest.mark.parametrize("command", ["grid", "map-cloud", "ndt-odom", "slam"])
@pytest.mark.parametrize("inside", [False, True])
def test_results_never_go_into_a_rosbag2_directory(command: str, inside: bool, recording: Path, capsys) -> None:
    out = recording / "results" if inside else recording
    before = snapshot(recording.parent)
    code, _, err = run([command, str(recording), "--out", str(out), "--force"], capsys)
    assert code == 2 and err.count("\n") == 1, err
    assert "lies inside the input" in err or "is the input" in err, err
    assert snapshot(recording.parent) == before


def test_an_output_directory_that_holds_the_bag_takes_only_the_named_files(tmp_path: Path, capsys) -> None:
    """`grid run.mcap --out .` is what users type: allowed, since only the command's own names are written."""
    bag = tmp_path / "run"
    shutil.copytree(BAG, bag)
    before = snapshot(bag)
    code, _, err = run(["grid", str(bag), "--out", str(tmp_path), "--no-mcap"], capsys)
    assert code == 0, err
    assert snapshot(bag) == before


@pytest.mark.parametrize("command, option, name", [
    ("grid", "--poses", "summary.json"),
    ("slam", "--relations", "trajectory.tum"),
])
def test_an_input_file_named_like_an_output_is_refused(command: str, option: str, name: str, tmp_path: Path,
                                                       capsys) -> None:
    """grid's --poses and slam's --relations are inputs: an output of the run with the same path is refused."""
    out = tmp_path / "out"
    out.mkdir()
    (out / name).write_text("1.0 2.0 0 0 0 0 0 1\n")
    before = snapshot(tmp_path)
    code, _, err = run([command, str(BAG), "--out", str(out), option, str(out / name), "--force"], capsys)
    assert code == 2 and "is the input" in err, err
    assert snapshot(tmp_path) == before


@pytest.mark.parametrize("layout", ["same", "bags inside out", "out inside a bag"])
def test_batch_refuses_an_output_directory_that_overlaps_its_bags(layout: str, tmp_path: Path, capsys) -> None:
    folder = tmp_path / "bags"
    shutil.copytree(BAG, folder / "run1")
    bags, out = {"same": ([folder], folder), "bags inside out": ([folder / "run1"], folder),
                 "out inside a bag": ([folder / "run1"], folder / "run1" / "results")}[layout]
    before = snapshot(tmp_path)
    code, _, err = run(["batch", "grid", *map(str, bags), "--out", str(out)], capsys)
    assert code == 2 and err.count("\n") == 1, err
    assert "holds the input" in err or "lies inside the input" in err or "is the input" in err, err
    assert snapshot(tmp_path) == before


@pytest.mark.parametrize("name", [".bagtools-x.tmp", ".bagtools-123.abc.tmp"])
def test_a_users_folder_named_like_staging_inside_out_is_never_removed(name: str, tmp_path: Path) -> None:
    out = tmp_path / "out"
    folder = out / name
    folder.mkdir(parents=True)
    (folder / "thesis.tex").write_text("precious")
    (folder / ".lock").write_text("")  # even with a file the old sweep took for its lock
    old = time.time() - 3600
    os.utime(folder, (old, old))
    with OutputDir(out, ["a.txt"]) as staged:
        (staged / "a.txt").write_text("a")
    assert (folder / "thesis.tex").read_text() == "precious"
    assert sorted(p.name for p in out.iterdir()) == sorted([name, "a.txt"])


def test_a_users_folder_named_like_staging_beside_an_output_file_is_never_removed(tmp_path: Path) -> None:
    folder = tmp_path / ".tf.csv.x.tmp"
    folder.mkdir()
    (folder / "data.bin").write_bytes(b"mine")
    old = time.time() - 3600
    os.utime(folder, (old, old))
    write_text_atomic(tmp_path / "tf.csv", "a,b\n")
    assert (folder / "data.bin").read_bytes() == b"mine"


def test_signals_are_held_while_staging_is_set_up_and_delivered_after() -> None:
    with pytest.raises(KeyboardInterrupt):
        with _signals_held():
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(0.05)
            reached = True  # the interrupt did not land inside the block
    assert reached


def test_an_interrupt_while_the_output_directory_is_set_up_leaves_nothing(tmp_path: Path, monkeypatch) -> None:
    """Ctrl-C landing between creating the staging directory and marking it (patched in, deterministically)."""
    import bagtools.outputs as outputs

    real_open = os.open

    def interrupted_open(path, *args, **kwargs):
        if str(path).endswith(".bagtools-staging.lock"):
            raise KeyboardInterrupt
        return real_open(path, *args, **kwargs)

    monkeypatch.setattr(outputs.os, "open", interrupted_open)
    out = tmp_path / "new" / "out"
    with pytest.raises(KeyboardInterrupt):
        with OutputDir(out, ["a.txt"]):
            pass
    with pytest.raises(KeyboardInterrupt):
        with atomic_path(tmp_path / "other" / "tf.csv"):
            pass
    assert list(tmp_path.iterdir()) == []


def test_a_failed_run_leaves_no_output_directory_behind(tmp_path: Path, capsys) -> None:
    out = tmp_path / "a" / "b" / "out"
    with pytest.raises(BagtoolsError):
        with OutputDir(out, ["a.txt"]) as staged:
            (staged / "a.txt").write_text("half")
            raise BagtoolsError("the writer failed", "x")
    assert list(tmp_path.iterdir()) == []
    code, _, err = run(["ndt-odom", str(tmp_path / "missing.mcap"), "--out", str(out)], capsys)
    assert code == 2 and list(tmp_path.iterdir()) == []


def test_a_failed_writer_in_a_directory_that_existed_keeps_the_directory(tmp_path: Path) -> None:
    out = tmp_path / "out"
    out.mkdir()
    with pytest.raises(BagtoolsError):
        with OutputDir(out, ["a.txt"]) as staged:
            (staged / "a.txt").write_text("half")
            raise BagtoolsError("the writer failed", "x")
    assert out.is_dir() and list(out.iterdir()) == []


@pytest.mark.parametrize("argv", [
    ["tf", "echo", str(BAG), "odom", "base_footprint", "--csv", "{out}"],
    ["tf", "frames", str(BAG), "--dot", "{out}"],
    ["export", str(BAG), "/odom", "--out", "{out}"],
])
def test_a_dangling_symlink_is_an_existing_output(argv: list[str], tmp_path: Path, capsys) -> None:
    link = tmp_path / ("out.csv" if "export" in argv else "out.txt")
    link.symlink_to(tmp_path / "elsewhere" / "target")
    code, _, err = run([a.replace("{out}", str(link)) for a in argv], capsys)
    assert code == 2 and "already exists" in err and "--force" in err, err
    assert link.is_symlink() and os.readlink(link) == str(tmp_path / "elsewhere" / "target")
    code, _, err = run([a.replace("{out}", str(link)) for a in argv] + ["--force"], capsys)
    assert code == 0, err
    assert link.is_file() and not link.is_symlink() and not (tmp_path / "elsewhere").exists()


def test_a_full_disk_is_said_and_names_the_output(tmp_path: Path, capsys, monkeypatch) -> None:
    """ENOSPC while writing: Parquet's 'Operation on closed file' from the close after it hid it, and an output
    directory's failure named the input bag. Both now say 'No space left on device' of the output."""
    import errno

    from bagtools.commands.export import sinks
    from bagtools.commands.grid import writer as grid_writer

    def full(*args, **kwargs):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    def closed(self):
        raise ValueError("Operation on closed file")  # what pyarrow's writer says after the failed write

    monkeypatch.setattr(sinks.ParquetSink, "write", full)
    monkeypatch.setattr(sinks.ParquetSink, "close", closed)
    out = tmp_path / "odom.parquet"
    code, _, err = run(["export", str(BAG), "/odom", "--out", str(out)], capsys)
    assert code == 2 and err == f"bagtools: {out}: cannot write: No space left on device\n", err
    assert list(tmp_path.iterdir()) == []
    monkeypatch.setattr(grid_writer, "render_map_png", full)  # the PNG is written into the staged directory
    grid_out = tmp_path / "grid"
    code, _, err = run(["grid", str(BAG), "--out", str(grid_out), "--no-mcap"], capsys)
    assert code == 2 and err.endswith(f"bagtools: {grid_out}: cannot write: No space left on device\n"), err
    assert not grid_out.exists()
