"""The messages of a scanned MCAP file (:func:`~bagtools.io.mcap_source.scan_mcap`), streamed in log-time order
from its readable segments (:func:`iter_segments`); a chunk the scan did not check is checked as it is read."""

from __future__ import annotations

import heapq
import io
from collections.abc import Iterable, Iterator
from pathlib import Path

from mcap.records import Chunk, Message
from mcap.stream_reader import StreamReader

from bagtools.io.mcap_chunk import READ_ERRORS, ChunkDamaged, ChunkMessage, chunk_records, decompress_chunk
from bagtools.io.mcap_source import McapScan, Segment, checked_records, damaged_after, read_cut_chunk


def iter_segments(path: Path, scan: McapScan, channel_ids: set[int] | None,
                  damage: list[str] | None = None) -> Iterator[Message | ChunkMessage]:
    """Messages of the readable segments of ``scan`` on ``channel_ids`` (all if None), in log-time order.

    A chunk of an unverified scan is checked as it is read: when it is damaged, what
    precedes the damage is yielded and one line is added to ``damage``.
    """
    segments = [s for s in scan.segments if channel_ids is None or s.channels & channel_ids]
    # later_start[i]: the earliest stamp any segment after i can hold.
    later_start = [0] * len(segments)
    running = None
    for i in range(len(segments) - 1, -1, -1):
        later_start[i] = running if running is not None else 1 << 64
        running = segments[i].start_ns if running is None else min(running, segments[i].start_ns)
    pending: list[tuple[int, int, Message | ChunkMessage]] = []
    seq = 0
    with path.open("rb") as f:
        size = f.seek(0, io.SEEK_END)
        for segment, release_below in zip(segments, later_start):
            batch = list(_segment_messages(f, size, scan, segment, damage, channel_ids))
            if not pending and (not batch or batch[-1].log_time <= release_below) and _in_order(batch):
                yield from batch  # the usual chunk: in order, and before every later one (no heap needed)
                continue
            for message in batch:
                heapq.heappush(pending, (message.log_time, seq, message))
                seq += 1
            while pending and pending[0][0] <= release_below:
                yield heapq.heappop(pending)[2]
    while pending:
        yield heapq.heappop(pending)[2]


def _in_order(messages: list[Message | ChunkMessage]) -> bool:
    return all(a.log_time <= b.log_time for a, b in zip(messages, messages[1:]))


def _segment_messages(f: io.BufferedReader, size: int, scan: McapScan, segment: Segment,
                      damage: list[str] | None, wanted: set[int] | None = None) -> Iterable[Message | ChunkMessage]:
    """Of the first ``segment.n_good`` messages of a segment (the readable ones, as the scan found, or, for an
    unverified scan, those before any damage its chunk shows now), those on ``wanted`` channels (all if None)."""
    taken = 0
    if segment.n_top_level:
        f.seek(segment.offset)
        records = StreamReader(f, skip_magic=True, emit_chunks=True, record_size_limit=size).records
        for record in records:
            if isinstance(record, Message):
                if wanted is None or record.channel_id in wanted:
                    yield record
                taken += 1
                if taken == segment.n_good:
                    return
        return
    if segment.partial_body:
        chunk = read_cut_chunk(f, segment.offset, size)
        data = decompress_chunk(chunk, allow_partial=True) if chunk is not None else b""
    else:
        f.seek(segment.offset)
        chunk = next(StreamReader(f, skip_magic=True, emit_chunks=True, record_size_limit=size).records)
        if not scan.verified:
            yield from _checked_messages(scan, segment, chunk, damage, wanted)
            return
        data = decompress_chunk(chunk)
    tally = [0]
    records = chunk_records(data, wanted, None, tally)
    while tally[0] < segment.n_good:
        try:
            record = next(records)
        except (StopIteration, *READ_ERRORS):
            return
        if isinstance(record, ChunkMessage) and tally[0] <= segment.n_good:
            yield record


def _checked_messages(scan: McapScan, segment: Segment, chunk: Chunk, damage: list[str] | None,
                      wanted: set[int] | None = None) -> Iterator[ChunkMessage]:
    """The messages (on ``wanted`` channels, all if None) of a chunk not checked at open, checked now; the damage
    met is said in ``damage``."""
    said = damage if damage is not None else []
    try:
        data = decompress_chunk(chunk)
    except ChunkDamaged as err:
        said.append(f"chunk at byte {segment.offset} {err}; its {segment.n_good} messages are skipped")
        return
    tally = [0]
    try:
        for record in checked_records(scan, chunk, data, wanted, tally):
            if isinstance(record, ChunkMessage):
                yield record
    except READ_ERRORS as err:
        said.append(damaged_after(segment.offset, tally[0], err))
        return
    taken = tally[0]
    if taken != segment.n_good:
        said.append(f"chunk at byte {segment.offset} holds {taken} messages, its message indexes "
                    f"{segment.n_good}")
