"""Which bags a batch finds (paths, globs, folders) and the unique names of their output directories."""

from __future__ import annotations

from pathlib import Path

import pytest

from bagtools.batch.bags import BATCH_MANIFEST, find_bags, output_names
from bagtools.errors import BagtoolsError


def _rosbag2(path: Path) -> Path:
    path.mkdir(parents=True)
    (path / "metadata.yaml").write_text("rosbag2_bagfile_information: {}\n")
    (path / f"{path.name}_0.mcap").write_bytes(b"x")
    return path


def _file(path: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(b"x")
    return path


@pytest.fixture
def tree(tmp_path: Path) -> Path:
    """day/ with rosbag2 bags at two depths, bare bag files, clutter, a hidden folder and a batch output."""
    day = tmp_path / "day"
    _rosbag2(day / "robot1" / "run1")
    _rosbag2(day / "robot2" / "run1")
    _rosbag2(day / "run7")
    _file(day / "loose.mcap")
    _file(day / "old" / "legacy.bag")
    _file(day / "old" / "notes.txt")
    _rosbag2(day / ".trash" / "gone")
    _file(day / "fleet" / BATCH_MANIFEST)
    _rosbag2(day / "fleet" / "run9")
    return day


def _rel(paths: list[Path], root: Path) -> list[str]:
    return [str(p.relative_to(root)) for p in paths]


def test_a_folder_is_searched_for_rosbag2_directories_and_bag_files(tree: Path) -> None:
    found = find_bags([str(tree)])
    assert _rel(found, tree) == ["loose.mcap", "old/legacy.bag", "robot1/run1", "robot2/run1", "run7"]
    assert all(p.is_absolute() for p in found)


def test_a_rosbag2_directory_is_one_bag_and_its_storage_is_not_searched(tree: Path) -> None:
    assert _rel(find_bags([str(tree / "run7")]), tree) == ["run7"]
    assert _rel(find_bags([str(tree / "run7" / "metadata.yaml")]), tree) == ["run7"]


def test_globs_keep_bags_and_drop_clutter_and_each_bag_is_listed_once(tree: Path) -> None:
    found = find_bags([str(tree / "robot*" / "run1"), str(tree / "old" / "*"), str(tree / "robot1" / "run1")])
    assert _rel(found, tree) == ["robot1/run1", "robot2/run1", "old/legacy.bag"]


def test_an_explicit_file_is_a_bag_whatever_it_holds(tree: Path) -> None:
    assert _rel(find_bags([str(tree / "old" / "notes.txt")]), tree) == ["old/notes.txt"]


def test_the_output_directory_is_never_searched(tree: Path) -> None:
    found = find_bags([str(tree)], skip=[tree / "robot2"])
    assert "robot2/run1" not in _rel(found, tree)


@pytest.mark.parametrize("arg, problem", [
    ("missing", "no such file or directory"),
    ("nothing*", "matches no file or directory"),
    ("empty", "holds no bag"),
])
def test_arguments_that_name_no_bag_are_refused(tree: Path, arg: str, problem: str) -> None:
    (tree / "empty").mkdir()
    with pytest.raises(BagtoolsError, match=problem):
        find_bags([str(tree / arg)])


def test_names_are_the_bags_own_when_unique() -> None:
    bags = [Path("/d/run1"), Path("/d/run2.mcap"), Path("/e/run3")]
    assert output_names(bags) == ["run1", "run2", "run3"]


def test_bags_sharing_a_name_get_their_folder_in_front() -> None:
    bags = [Path("/data/robot1/run1"), Path("/data/robot2/run1"), Path("/data/run2")]
    assert output_names(bags) == ["robot1__run1", "robot2__run1", "run2"]


def test_names_still_equal_reserved_or_hidden_get_a_hash_of_the_path() -> None:
    bags = [Path("/x/a/run1"), Path("/y/a/run1"), Path("/z/fleet.csv"), Path("/z/.hidden")]
    names = output_names(bags)
    assert len(set(names)) == 4
    assert names[0].startswith("run1-") and names[1].startswith("run1-") and len(names[0]) == len("run1-") + 8
    assert names[2].startswith("fleet.csv-") and names[3].startswith("hidden-")
    assert output_names(bags) == names  # deterministic


def test_a_bag_file_is_named_without_its_suffix(tree: Path) -> None:
    assert output_names([tree / "loose.mcap", tree / "run7"]) == ["loose", "run7"]
