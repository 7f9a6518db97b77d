"""Damaged MCAP files: every readable message is read, in order, and the damage is said in a warning."""

from __future__ import annotations

import struct
from pathlib import Path

import pytest
from mcap.records import Chunk, ChunkIndex
from mcap.stream_reader import StreamReader
from rosbags.highlevel import AnyReader

from bagtools.errors import BagError
from bagtools.io import open_bag
from bagtools.io.mcap_messages import iter_segments
from bagtools.io.mcap_source import scan_mcap
from tests.conftest import FIXTURES

SOURCE = FIXTURES / "sim_lap_cloud_20s" / "sim_lap_cloud_20s.mcap"


def records_with_offsets(path: Path) -> list[tuple[int, object]]:
    with path.open("rb") as f:
        f.read(8)
        out, position = [], 8
        for record in StreamReader(f, skip_magic=True, emit_chunks=True).records:
            out.append((position, record))
            position = f.tell()
    return out


def all_messages(path: Path) -> list[tuple[str, int, bytes]]:
    with open_bag(path) as bag:
        return [(r.topic, r.log_time_ns, bytes(r.raw)) for r in bag.raw_messages()]


@pytest.fixture(scope="module")
def layout() -> dict:
    recs = records_with_offsets(SOURCE)
    chunks = [(p, r) for p, r in recs if isinstance(r, Chunk)]
    assert len(chunks) >= 2
    return {"chunks": chunks, "chunk_indexes": [(p, r) for p, r in recs if isinstance(r, ChunkIndex)],
            "reference": all_messages(SOURCE)}


def damaged(tmp_path: Path, edit) -> Path:
    data = bytearray(SOURCE.read_bytes())
    edit(data)
    path = tmp_path / "damaged.mcap"
    path.write_bytes(bytes(data))
    return path


def test_intact_file_reads_exactly_what_rosbags_reads() -> None:
    with AnyReader([SOURCE]) as reader:
        expected = [(c.topic, t, bytes(raw)) for c, t, raw in reader.messages()]
    assert all_messages(SOURCE) == expected


def _ordered_subset(part: list, whole: list) -> bool:
    it = iter(whole)
    return all(any(x == y for y in it) for x in part)


@pytest.mark.parametrize("how", ["bad_crc", "huge_uncompressed_size", "flipped_bits"])
def test_bad_chunk_is_skipped_with_a_count(how: str, layout: dict, tmp_path: Path) -> None:
    position, chunk = layout["chunks"][-1]

    def edit(data: bytearray) -> None:
        if how == "bad_crc":
            struct.pack_into("<I", data, position + 9 + 24, 0xDEADBEEF)
        elif how == "huge_uncompressed_size":
            struct.pack_into("<Q", data, position + 9 + 16, 9 * 2**40)  # 9 TiB: must not be allocated
        else:
            for k in range(position + 300, position + 2000, 97):
                data[k] ^= 0xFF

    path = damaged(tmp_path, edit)
    with open_bag(path) as bag:
        # The size lie shows in the chunk's head, against the summary: the file is walked at open. A bad
        # CRC or flipped bits show only in the chunk's data: it is checked, and the damage said, as it is read.
        checked_at_open = how == "huge_uncompressed_size"
        assert bool(bag.warnings) == checked_at_open
        got = [(r.topic, r.log_time_ns, bytes(r.raw)) for r in bag.raw_messages()]
        warnings = list(bag.warnings)
        assert (bag.message_count == len(got)) == checked_at_open
    assert len(warnings) == 1 and "damaged MCAP" in warnings[0] and f"chunk at byte {position}" in warnings[0]
    assert ("known to be lost" if checked_at_open else "messages are skipped") in warnings[0] \
        or "is damaged after" in warnings[0]
    reference = layout["reference"]
    assert 0 < len(got) < len(reference)
    if how != "flipped_bits":  # no CRC in this file: flipped records before the detected damage may pass
        assert _ordered_subset(got, reference)


def test_damaged_record_length_resumes_at_the_next_chunk(layout: dict, tmp_path: Path) -> None:
    path = damaged(tmp_path, lambda d: d.__setitem__(8 + 1 + 5, d[8 + 1 + 5] ^ 0xFF))  # the header's length
    with open_bag(path) as bag:
        assert any("resumed at the next chunk" in w for w in bag.warnings)
    assert all_messages(path) == layout["reference"]


def test_damaged_chunk_length_of_last_chunk_is_damage_not_truncation(layout: dict, tmp_path: Path) -> None:
    position, _ = layout["chunks"][-1]
    path = damaged(tmp_path, lambda d: struct.pack_into("<Q", d, position + 1, 2**40))
    with open_bag(path) as bag:
        assert any("damaged MCAP" in w and "unreadable" in w for w in bag.warnings)
        assert not any("truncated" in w for w in bag.warnings)
    got = all_messages(path)
    assert 0 < len(got) < len(layout["reference"]) and _ordered_subset(got, layout["reference"])


def test_wrong_summary_offsets_cost_nothing_but_are_said(layout: dict, tmp_path: Path) -> None:
    def edit(data: bytearray) -> None:
        for position, index in layout["chunk_indexes"]:
            struct.pack_into("<Q", data, position + 9 + 16, index.chunk_start_offset + 13)

    path = damaged(tmp_path, edit)
    with open_bag(path) as bag:
        assert len(bag.warnings) == 1 and "summary section disagree with the data" in bag.warnings[0]
    assert all_messages(path) == layout["reference"]


def test_missing_closing_magic_is_said(layout: dict, tmp_path: Path) -> None:
    path = damaged(tmp_path, lambda d: d.__delitem__(slice(-1, None)))
    with open_bag(path) as bag:
        assert any("without its closing magic" in w for w in bag.warnings)
    assert all_messages(path) == layout["reference"]


def test_every_chunk_bad_is_a_one_line_error(layout: dict, tmp_path: Path) -> None:
    def edit(data: bytearray) -> None:
        for position, _ in layout["chunks"]:
            struct.pack_into("<I", data, position + 9 + 24, 0xDEADBEEF)

    with open_bag(damaged(tmp_path, edit)) as bag:  # the chunks' heads and indexes agree with the summary
        with pytest.raises(BagError, match="damaged MCAP: no message could be read .*: chunk at byte"):
            list(bag.raw_messages())
    scan = scan_mcap(damaged(tmp_path, edit), verify=True)  # the walk that checks every chunk finds it at once
    assert scan.message_count == 0 and all("checksum mismatch" in d for d in scan.damage)


def test_intact_file_opens_from_its_summary_and_reads_the_same(layout: dict) -> None:
    fast, walked = scan_mcap(SOURCE, verify=False), scan_mcap(SOURCE, verify=True)
    assert not fast.verified and walked.verified and not fast.damage
    assert (fast.counts, fast.start_ns, fast.end_ns, fast.profile, fast.metadata) == (
        walked.counts, walked.start_ns, walked.end_ns, walked.profile, walked.metadata)
    assert [(s.offset, s.start_ns, s.n_good, s.channels) for s in fast.segments] == [
        (s.offset, s.start_ns, s.n_good, s.channels) for s in walked.segments]
    assert [(m.channel_id, m.log_time, bytes(m.data)) for m in iter_segments(SOURCE, fast, None)] == [
        (m.channel_id, m.log_time, bytes(m.data)) for m in iter_segments(SOURCE, walked, None)]


def test_damage_in_the_first_chunk_loses_its_messages_not_the_run(layout: dict, tmp_path: Path) -> None:
    """The first chunk held /tf_static and /simulation/world: grid, slam and map-cloud said "no message could be
    read" although the other chunks were intact. Now a topic wholly in damaged chunks is named as such, the
    simulator's world (only for scoring) is done without, and the commands map what is left, saying the damage."""
    import subprocess
    import sys

    def edit(data: bytearray) -> None:
        position, _ = layout["chunks"][0]
        struct.pack_into("<I", data, position + 9 + 24, 0xDEADBEEF)

    bag = damaged(tmp_path, edit)
    with open_bag(bag) as reader:
        with pytest.raises(BagError, match=r"no message of /tf_static could be read \(all of it lay in damaged chunks"):
            list(reader.raw_messages(["/tf_static"]))
    for command in ("grid", "slam"):
        done = subprocess.run([sys.executable, "-m", "bagtools", command, str(bag), "--out", str(tmp_path / command),
                               "--no-mcap"], capture_output=True, text=True, timeout=600)
        assert done.returncode == 0 and "damaged MCAP" in done.stderr, done.stderr
