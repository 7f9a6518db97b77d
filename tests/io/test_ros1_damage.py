"""A damaged chunk of a ROS 1 bag costs its own messages, not the rest of the bag (#42): the index at the end of
the file finds every chunk after it."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from rosbags.rosbag1 import Reader, Writer
from rosbags.typesys import Stores, get_typestore

from bagtools.io import open_bag

N = 600


def _bag(path: Path) -> list[tuple[int, int, int]]:
    """A ROS 1 bag of N String messages 0.1 s apart in small chunks; its chunks (pos, data start, data size)."""
    store = get_typestore(Stores.ROS1_NOETIC)
    string = store.types["std_msgs/msg/String"]
    with Writer(path) as writer:
        writer.chunk_threshold = 2000  # about 20 messages a chunk
        conn = writer.add_connection("/chatter", string.__msgtype__, typestore=store)
        for i in range(N):
            data = store.serialize_ros1(string(data=f"message {i:04d} " + "x" * 40), string.__msgtype__)
            writer.write(conn, 1_000_000_000 + i * 100_000_000, data)
    with Reader(path) as reader:
        return [(pos, c.datapos, c.datasize) for pos, c in sorted(reader.chunks.items())]


def _damage(path: Path, start: int, length: int) -> None:
    data = bytearray(path.read_bytes())
    data[start:start + length] = bytes(length)
    path.write_bytes(bytes(data))


def _read(path: Path) -> tuple[list[str], list[str]]:
    bag = open_bag(path)
    texts = [bytes(rec.msg.data, "ascii").decode() if isinstance(rec.msg.data, str) else rec.msg.data
             for rec in bag.messages(["/chatter"])]
    return texts, bag.warnings


@pytest.mark.parametrize("which", ["first", "middle"])
def test_a_damaged_chunk_is_skipped_and_the_bag_read_on(tmp_path: Path, which: str) -> None:
    path = tmp_path / "damaged.bag"
    chunks = _bag(path)
    pos, data_start, size = chunks[0] if which == "first" else chunks[len(chunks) // 2]
    _damage(path, data_start, size)  # none of its messages can be read
    texts, warnings = _read(path)
    lost = N - len(texts)
    assert 10 <= lost <= 40, lost  # one chunk's worth
    assert texts[-1] == f"message {N - 1:04d} " + "x" * 40  # read to the end
    assert texts == sorted(texts)
    assert any(f"damaged ROS 1 bag: the chunk at byte {pos} cannot be read: {lost} message(s)" in w and
               "read on past it" in w for w in warnings), warnings


def test_damage_in_the_last_chunk_ends_the_read_there_and_says_so(tmp_path: Path) -> None:
    path = tmp_path / "damaged.bag"
    chunks = _bag(path)
    _damage(path, chunks[-1][1], chunks[-1][2])
    texts, warnings = _read(path)
    assert len(texts) < N and texts[-1] < f"message {N - 1:04d}"
    assert any("the rest of the bag could not be read" in w for w in warnings), warnings


def test_info_on_a_bag_with_a_damaged_chunk_counts_what_it_read(tmp_path: Path) -> None:
    path = tmp_path / "damaged.bag"
    chunks = _bag(path)
    _damage(path, chunks[len(chunks) // 2][1], chunks[len(chunks) // 2][2])
    done = subprocess.run([sys.executable, "-m", "bagtools", "info", str(path)], capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 0, done.stderr
    assert "read on past it" in done.stderr and "Traceback" not in done.stderr
    count = next(line for line in done.stdout.splitlines() if line.startswith("messages:"))
    assert N - 40 <= int(count.split()[1]) < N
