"""A corpus of damaged and odd inputs for every bagtools command, each with what bagtools must do.

``build_corpus(dest, size)`` writes the inputs under ``dest/inputs`` and returns
:class:`Case` objects; each case has one or more :class:`Run` (a command line,
its expectation, and the output directory it must not damage). The promise
being tested (README, ``bagtools/errors.py``):

- bad input: ONE line on stderr, ``bagtools: <file>: <problem>``, exit status 2,
  no traceback;
- outputs are written atomically and never overwritten without ``--force``; a
  failed run changes nothing in ``--out``; with ``--force`` a run may replace
  only the command's own output names;
- no process is killed for memory (the runner limits the address space, so a
  decoder that believes a lying size field fails with MemoryError);
- a wrong-but-plausible input gets ``bagtools: warning: ...`` or a refusal.

Expectations (see :func:`tests.robustness.runner.judge`): ``error`` (exit 2,
one line naming the file at fault), ``warn_or_error`` (exit 0 with a warning,
or such an error), ``ok`` (exit 0: odd but valid; warnings allowed) and
``any`` (exit 0 or such an error: damage no reader can detect, e.g. a flipped
bit in a float of an unchecksummed chunk, or a value either answer is right for).

Every ``--out`` run starts from a directory prefilled with user files
(``notes.txt``, ``user_data/measurements.csv``) and the command's own output
names from "an earlier good run", and passes ``--force``: the run may replace
only its own names on success, and must leave every byte as it was on failure.
"""

from __future__ import annotations

import json
import math
import os
import random
import shutil
import sqlite3
import struct
import zlib
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from tests.robustness import damage as D
from tests.robustness.scene import S, T0, Cloud, Odom, Scan, Scene, Tf, edit, make_scene, yaw_quat

REPO = Path(__file__).resolve().parents[2]
FIXTURES = REPO / "fixtures"
REAL_DIR = REPO.parent / "shared" / "data" / "real"
LAP = FIXTURES / "sim_lap_cloud_20s"
RANDOM = FIXTURES / "sim_random_nocloud_20s"

# The output names each command documents (README); a successful --force run may replace only these.
OWN_OUTPUTS = {
    "tf point": ("point.csv", "point.png", "summary.json"),
    "map-cloud": ("cloud_map.pcd", "cloud_map.ply", "cloud_map.png", "summary.json", "results.mcap"),
    "ndt-odom": ("trajectory.tum", "odometry.tum", "ground_truth.tum", "trajectory.png", "scan_map.png", "summary.json",
                 "results.mcap"),
    "grid": ("map.pgm", "map.yaml", "map.png", "summary.json", "results.mcap"),
    "slam": ("trajectory.tum", "odometry.tum", "ground_truth.tum", "pose_graph.g2o", "map.pgm", "map.yaml", "map.png",
             "summary.json", "results.mcap"),
}
USER_FILES: dict[str, bytes | None] = {
    "notes.txt": b"my notes about this run: keep them\n",
    "user_data": None,
    "user_data/measurements.csv": b"t,x,y\n0,1,2\n",
}
EARLIER_OUTPUT = b"output of an earlier good run\n"
FIXED_MTIME_NS = 1_600_000_000 * S

EXPECTATIONS = ("error", "warn_or_error", "ok", "any")
ALL_COMMANDS = ("info", "tf frames", "tf echo", "tf point", "map-cloud", "ndt-odom", "grid", "slam")


@dataclass
class Run:
    """One command line over a case's input.

    ``watch`` is the directory (usually ``--out``) whose bytes a failed run must
    not change; :meth:`prepare` recreates it from ``prefill`` (relative path ->
    bytes, None for a directory) before every run, or removes it when ``prefill``
    is None. ``own`` are the top-level names a successful run may replace.
    ``names``: the error line must contain one of them (the file at fault).
    """

    command: str
    argv: list[str]
    expect: str
    watch: Path | None = None
    prefill: dict[str, bytes | None] | None = None
    own: tuple[str, ...] = ()
    names: tuple[str, ...] = ()

    def prepare(self) -> None:
        if self.watch is None:
            return
        if self.watch.is_dir() and not self.watch.is_symlink():
            for p in self.watch.rglob("*"):   # a run may have left read-only files
                if p.is_dir() and not p.is_symlink():
                    p.chmod(0o755)
            shutil.rmtree(self.watch)
        elif os.path.lexists(self.watch):
            self.watch.unlink()
        if self.prefill is None:
            self.watch.parent.mkdir(parents=True, exist_ok=True)
            return
        self.watch.mkdir(parents=True)
        for rel, content in sorted(self.prefill.items()):
            p = self.watch / rel
            if content is None:
                p.mkdir(parents=True, exist_ok=True)
            else:
                p.parent.mkdir(parents=True, exist_ok=True)
                p.write_bytes(content)
                os.utime(p, ns=(FIXED_MTIME_NS, FIXED_MTIME_NS))

    def job(self, timeout_s: float, mem_limit_bytes: int) -> dict:
        """Keyword arguments of :func:`tests.robustness.runner.start_case` (plus ``prepare``)."""
        return {"argv": self.argv, "out_dir": self.watch, "timeout_s": timeout_s, "mem_limit_bytes": mem_limit_bytes,
                "own": self.own, "names": self.names, "prepare": self.prepare}


@dataclass
class Case:
    """A damaged or odd input and the runs over it.

    ``group`` says what kind of input it is (for the report), ``expect`` the
    expectation of most runs (each :class:`Run` has its own), ``skip`` a reason
    not to run it on this machine.
    """

    name: str
    group: str
    path: Path | None
    expect: str
    runs: list[Run]
    note: str = ""
    skip: str | None = None

    @property
    def commands(self) -> list[str]:
        return [r.command for r in self.runs]


@dataclass(frozen=True)
class Profile:
    """What a bag holds, so the standard command lines fit it."""

    fixed: str = "map"
    base: str = "base_link"
    cloud_topic: str | None = "/camera/depth/points"
    scan_topic: str | None = "/scan"
    sample: str | None = None
    ground_truth: bool = False

    def supports(self, command: str) -> bool:
        if command in ("map-cloud",):
            return self.cloud_topic is not None or self.scan_topic is not None
        if command in ("map-cloud scan", "ndt-odom", "grid", "slam"):
            return self.scan_topic is not None
        if command == "grid gt":
            return self.scan_topic is not None and self.ground_truth
        return True


SCENE = Profile(sample="1", ground_truth=True)
LAP_PROFILE = Profile(ground_truth=True)
RANDOM_PROFILE = Profile(cloud_topic=None, ground_truth=True)
TF_EXAMPLE = Profile(fixed="odom", cloud_topic=None, scan_topic=None)
NAV2 = Profile(fixed="map", cloud_topic=None, scan_topic=None)
TURTLEBOT3 = Profile(fixed="odom", cloud_topic=None)
CSAIL = Profile(fixed="odom", cloud_topic=None, ground_truth=True)


# ---------------------------------------------------------------------------- the builder


class _Builder:
    def __init__(self, dest: Path, size: str) -> None:
        if size not in ("small", "full"):
            raise ValueError(f"size must be 'small' or 'full', got {size!r}")
        self.dest = dest
        self.full = size == "full"
        self.inputs = dest / "inputs"
        self.outs = dest / "out"
        for d in (self.inputs, self.outs):
            if d.exists():
                shutil.rmtree(d)
            d.mkdir(parents=True)
        self.cases: list[Case] = []
        self.names: set[str] = set()
        self._scene: Scene | None = None
        self._scene_bags: dict[str, Path] = {}
        self._cursor: dict[tuple[str, ...], int] = {}

    # -- files -------------------------------------------------------------------

    def file(self, rel: str, data: bytes) -> Path:
        p = self.inputs / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_bytes(data)
        return p

    def bag_dir(self, rel: str, metadata: bytes | None, storage_name: str, storage: bytes) -> Path:
        """A rosbag2 directory with ``metadata`` (None: no metadata.yaml) and one storage file."""
        d = self.inputs / rel
        d.mkdir(parents=True)
        if metadata is not None:
            (d / "metadata.yaml").write_bytes(metadata)
        (d / storage_name).write_bytes(storage)
        return d

    @property
    def scene(self) -> Scene:
        if self._scene is None:
            self._scene = make_scene()
        return self._scene

    def scene_bag(self, kind: str) -> Path:
        """The undamaged scene as 'mcap' (zstd), 'plain' (uncompressed MCAP), 'sqlite3' or 'ros1'."""
        if kind not in self._scene_bags:
            base = self.inputs / "scene"
            base.mkdir(exist_ok=True)
            if kind == "ros1":
                path = self.scene.write(base / "scene_ros1.bag", storage="ros1")
            elif kind == "sqlite3":
                path = self.scene.write(base / "scene_sqlite3", storage="sqlite3")
            else:
                path = self.scene.write(base / f"scene_{kind}", compression=(kind == "mcap"))
            self._scene_bags[kind] = path
        return self._scene_bags[kind]

    def write_scene(self, rel: str, scene: Scene, storage: str = "mcap") -> Path:
        p = self.inputs / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        return scene.write(p, storage=storage)

    # -- runs --------------------------------------------------------------------

    def out_dir(self, case: str, label: str) -> Path:
        return self.outs / case / label.replace(" ", "_")

    def prefilled(self, command: str) -> dict[str, bytes | None]:
        """User files plus the command's own output names from an earlier run."""
        return {**USER_FILES, **{name: EARLIER_OUTPUT for name in OWN_OUTPUTS.get(command, ())}}

    def std_run(self, case: str, command: str, bag: Path | str, prof: Profile, expect: str,
                names: tuple[str, ...] | None = None, extra: list[str] | None = None, label: str | None = None) -> Run:
        """The standard command line of ``command`` over ``bag`` (outputs into a prefilled --out with --force)."""
        bag = str(bag)
        names = (bag,) if names is None else names
        extra = list(extra or [])
        label = label or command
        if command == "info":
            return Run(label, ["info", bag, *extra], expect, names=names)
        if command == "tf frames":
            return Run(label, ["tf", "frames", bag, *extra], expect, names=names)
        if command == "tf echo":
            return Run(label, ["tf", "echo", bag, prof.fixed, prof.base, *extra], expect, names=names)
        out = self.out_dir(case, label)
        key = "map-cloud" if command.startswith("map-cloud") else "grid" if command.startswith("grid") else command
        common = dict(watch=out, prefill=self.prefilled(key), own=OWN_OUTPUTS[key], names=names)
        if command == "tf point":
            argv = ["tf", "point", bag, "--out", str(out), "--point", "1", "0", "0", "--frame", prof.fixed, "--force"]
        elif command.startswith("map-cloud"):
            argv = ["map-cloud", bag, "--out", str(out), "--frame", prof.fixed, "--force"]
            if command == "map-cloud scan" or prof.cloud_topic is None:
                argv += ["--topic", str(prof.scan_topic)]
            elif prof.cloud_topic != "/camera/depth/points":
                argv += ["--topic", prof.cloud_topic]
            if prof.sample:
                argv += ["--sample", prof.sample]
        elif command in ("ndt-odom", "slam"):
            argv = [command, bag, "--out", str(out), "--force"]
            if prof.scan_topic != "/scan":
                argv += ["--topic", str(prof.scan_topic)]
        elif command.startswith("grid"):
            argv = ["grid", bag, "--out", str(out), "--frame", prof.fixed, "--force"]
            if command == "grid gt":
                argv += ["--poses", "ground-truth"]
            if prof.scan_topic != "/scan":
                argv += ["--topic", str(prof.scan_topic)]
        else:
            raise ValueError(command)
        return Run(label, argv + extra, expect, **common)

    def add(self, name: str, group: str, path: Path | None, commands: tuple[str, ...] | list[str],
            expect: str | dict[str, str], prof: Profile = SCENE, note: str = "", names: tuple[str, ...] | None = None,
            skip: str | None = None) -> Case:
        """A case running the standard command lines of ``commands`` over ``path``.

        ``expect``: one expectation, or a dict command -> expectation with '*' for the rest.
        """
        if name in self.names:
            raise ValueError(f"duplicate case name {name}")
        self.names.add(name)
        runs = []
        for command in commands:
            if not prof.supports(command):
                continue
            exp = expect if isinstance(expect, str) else expect.get(command, expect["*"])
            runs.append(self.std_run(name, command, path, prof, exp, names=names))
        default = expect if isinstance(expect, str) else expect["*"]
        case = Case(name, group, path, default, runs, note, skip)
        self.cases.append(case)
        return case

    def add_runs(self, name: str, group: str, path: Path | None, runs: list[Run], note: str = "",
                 skip: str | None = None) -> Case:
        if name in self.names:
            raise ValueError(f"duplicate case name {name}")
        self.names.add(name)
        case = Case(name, group, path, runs[0].expect, runs, note, skip)
        self.cases.append(case)
        return case

    def pick(self, small: tuple[str, ...], full: tuple[str, ...] = ALL_COMMANDS) -> tuple[str, ...]:
        return full if self.full else small

    def rot(self, pool: tuple[str, ...], k_small: int = 1, k_full: int = 3) -> tuple[str, ...]:
        """``k`` commands of ``pool`` in turn (the next call continues where this one stopped), so that a
        family of similar inputs meets every command without running every command on every input."""
        k = min(len(pool), k_full if self.full else k_small)
        start = self._cursor.get(pool, 0)
        self._cursor[pool] = (start + k) % len(pool)
        return tuple(pool[(start + i) % len(pool)] for i in range(k))


# ---------------------------------------------------------------------------- MCAP damage


def _mcap_damages(data: bytes, rng: random.Random, full: bool, uncompressed: bool = False
                  ) -> list[tuple[str, bytes, str]]:
    """(name, damaged bytes, expectation) for one MCAP file."""
    L = D.mcap_layout(data)
    out: list[tuple[str, bytes, str]] = []
    c0, cl = L.chunks[0], L.chunks[-1]
    summary_start = L.summary_start or len(data)

    # Truncation: the reader recovers up to the cut (with a warning) or refuses.
    offsets = {5, c0.data_at + 100, cl.data_at + cl.data_len // 2, summary_start, len(data) - 1}
    if full:
        offsets |= {8, L.records[0].end, c0.record.offset + 5, c0.data_at + 1, c0.data_at + c0.data_len // 2,
                    c0.record.end, cl.record.end - 1, summary_start + 10, len(data) - 8}
        for op in (D.OP_SCHEMA, D.OP_CHUNK_INDEX):
            recs = [r for r in L.of(op) if r.offset >= summary_start]
            if recs:
                offsets.add(recs[0].offset + 3)
        if L.footer:
            offsets.add(L.footer.offset + 5)
        offsets |= {rng.randrange(8, len(data)) for _ in range(3)}
    for n in sorted(o for o in offsets if 0 < o < len(data)):
        out.append((f"trunc-{n}", data[:n], "error" if n < 8 else "warn_or_error"))

    # Damage inside compressed chunk data: with the chunk's CRC set right first, any change is detectable.
    def in_chunk(chunk: D.McapChunk, frac: float) -> int:
        return chunk.data_at + int(chunk.data_len * frac)

    zero_runs = [(c0, 0.5, 256)] + ([(c0, 0.1, 16), (c0, 0.9, 4096), (cl, 0.5, 4096), (cl, 0.3, 16)] if full else [])
    for chunk, frac, length in zero_runs:
        i = L.chunks.index(chunk)
        good_crc = D.with_correct_crc(data, chunk)
        out.append((f"chunk{i}-crc-set-zero{length}-at{int(frac * 100)}pct",
                    D.zero_run(good_crc, in_chunk(chunk, frac), length), "warn_or_error"))
    flips = [(c0, 1)] + ([(c0, 8), (c0, 64), (cl, 1), (cl, 8)] if full else [])
    for chunk, k in flips:
        i = L.chunks.index(chunk)
        good_crc = D.with_correct_crc(data, chunk)
        pos = D.random_positions(rng, chunk.data_at + 16, chunk.data_at + chunk.data_len, k)
        out.append((f"chunk{i}-crc-set-flip{k}", D.flip_bits(good_crc, pos), "warn_or_error"))
    if full:  # as written (CRC 0 = unchecked): not detectable in general
        out.append(("chunk0-crc0-zero256", D.zero_run(data, in_chunk(c0, 0.6), 256), "any"))
        pos = D.random_positions(rng, c0.data_at + 16, c0.data_at + c0.data_len, 4)
        out.append(("chunk0-crc0-flip4", D.flip_bits(data, pos), "any"))

    # A wrong nonzero CRC.
    out.append(("chunk0-bad-crc", D.put(data, c0.crc_at, "<I", 0xDEADBEEF), "warn_or_error"))
    if full and cl is not c0:
        out.append(("chunklast-bad-crc", D.put(data, cl.crc_at, "<I", 0x12345678), "warn_or_error"))

    # Lying sizes and offsets in the chunk record and the summary's chunk index.
    # The chunk record's own size field (readers that trust the summary's chunk index never see it).
    out.append(("chunk0-usize-2^40", D.put(data, c0.usize_at, "<Q", 1 << 40), "any"))
    cis = L.of(D.OP_CHUNK_INDEX)
    if cis:
        f0 = D.chunk_index_fields(data, cis[0])
        out.append(("chunkindex0-offset+1", D.put(data, f0["chunk_start_offset"], "<Q", c0.record.offset + 1),
                    "warn_or_error"))
        out.append(("chunkindex0-usize-2^40", D.put(data, f0["uncompressed_size"], "<Q", 1 << 40), "warn_or_error"))
        if full:
            for label, key, value in (("offset-0", "chunk_start_offset", 0),
                                      ("offset-past-eof", "chunk_start_offset", len(data) + 1000),
                                      ("offset-2^63", "chunk_start_offset", (1 << 63) - 1),
                                      ("length-2^62", "chunk_length", 1 << 62),
                                      ("csize-2^40", "compressed_size", 1 << 40),
                                      ("csize-1", "compressed_size", 1),
                                      ("usize-1", "uncompressed_size", 1),
                                      ("msgindex-length-2^62", "message_index_length", 1 << 62)):
                out.append((f"chunkindex0-{label}", D.put(data, f0[key], "<Q", value), "warn_or_error"))
            if len(cis) > 1:
                fl = D.chunk_index_fields(data, cis[-1])
                out.append(("chunkindexlast-offset-into-chunk0", D.put(data, fl["chunk_start_offset"], "<Q",
                                                                       c0.data_at + 7), "warn_or_error"))
    if full:
        out.append(("chunk0-record-length-2^62", D.put(data, c0.record.offset + 1, "<Q", 1 << 62), "warn_or_error"))
        comp_at = c0.record.body + 32
        if c0.compression:
            out.append(("chunk0-compression-unknown", D.overwrite(data, comp_at, b"lz5x"[:len(c0.compression)]),
                        "warn_or_error"))
        if L.footer:
            fb = L.footer.body
            for label, at, value in (("summary-start-0", fb, 0), ("summary-start-into-chunk", fb, c0.data_at + 3),
                                     ("summary-start-2^62", fb, 1 << 62), ("summary-offset-start-2^62", fb + 8, 1 << 62)):
                out.append((f"footer-{label}", D.put(data, at, "<Q", value), "warn_or_error"))
        hdr = L.records[0]
        out.append(("header-profile-length-2^31", D.put(data, hdr.body, "<I", 0x7FFFFFFF), "warn_or_error"))
        out.append(("header-opcode-garbage", D.put(data, hdr.offset, "<B", 0x41), "warn_or_error"))
        out.append(("header-record-length-2^62", D.put(data, hdr.offset + 1, "<Q", 1 << 62), "warn_or_error"))
    out.append(("magic-broken", D.put(data, 1, "<B", ord("X")), "error"))

    # Schemas and channels in the summary (what rosbags reads) ...
    schemas = [r for r in L.of(D.OP_SCHEMA) if r.offset >= summary_start]
    channels = [r for r in L.of(D.OP_CHANNEL) if r.offset >= summary_start]
    out += _schema_channel_damage(data, schemas, channels, rng, full, "summary")
    # ... and inside an uncompressed chunk (what a reader walking the data section reads).
    if uncompressed:
        inner = [r for c in L.chunks for r in c.inner]
        # The data section's copies of schemas and channels: a reader using the summary's copies reads
        # correct data, so either answer is right; it must not crash.
        out += [(name, damaged, "any") for name, damaged, _ in _schema_channel_damage(
            data, [r for r in inner if r.opcode == D.OP_SCHEMA], [r for r in inner if r.opcode == D.OP_CHANNEL],
            rng, full, "chunk")]
        out += _inner_message_damage(data, inner, full)

    # Statistics claiming no messages: the storage has them; trust the storage.
    stats = L.of(D.OP_STATISTICS)
    if stats:
        out.append(("statistics-counts-0", _zero_statistics(data, stats[0]), "ok"))
    # Fields a reader may legitimately never look at (it reads chunks through the summary's chunk index, and
    # MCAP readers must skip records of unknown opcode): the data stays intact, so reading it silently is as
    # right as a warning or a refusal; only a crash is wrong.
    unused = ("chunk0-compression-unknown", "chunk0-record-length-2^62", "chunkindex0-length-2^62",
              "chunkindex0-msgindex-length-2^62", "footer-summary-offset-start-2^62", "footer-summary-start-0",
              "footer-summary-start-2^62", "header-opcode-garbage", "summary-schema-tf-encoding-garbage",
              "summary-channel-tf-encoding-garbage", "chunk-tf-message-channel-999")
    out = [(name, damaged, "any" if name in unused else expect) for name, damaged, expect in out]
    return [d for d in out if d[1] != data]  # a damage that changed no byte is no case


def _named(data: bytes, recs: list[D.McapRecord], fields: Callable, key: str, needle: bytes) -> D.McapRecord | None:
    for r in recs:
        at, n = fields(data, r)[key]
        if needle in data[at + 4:at + 4 + n]:
            return r
    return recs[0] if recs else None


def _schema_channel_damage(data: bytes, schemas: list[D.McapRecord], channels: list[D.McapRecord],
                           rng: random.Random, full: bool, where: str) -> list[tuple[str, bytes, str]]:
    out: list[tuple[str, bytes, str]] = []
    tf_schema = _named(data, schemas, D.schema_fields, "name", b"TFMessage")
    if tf_schema is not None:
        f = D.schema_fields(data, tf_schema)
        at, n = f["data"]
        out.append((f"{where}-schema-tf-garbage-text", D.overwrite(data, at + 4, D.garbage_text(rng, n)),
                    "warn_or_error"))
        if full:
            nat, nn = f["name"]
            out.append((f"{where}-schema-tf-name-flipped", D.put(data, nat + 4 + nn - 3, "<B", ord("X")),
                        "warn_or_error"))
            eat, en = f["encoding"]
            out.append((f"{where}-schema-tf-encoding-garbage", D.overwrite(data, eat + 4, b"x" * en), "warn_or_error"))
            out.append((f"{where}-schema-tf-data-length-2^31", D.put(data, at, "<I", 0x7FFFFFFF), "warn_or_error"))
    if full:
        scan_schema = _named(data, schemas, D.schema_fields, "name", b"LaserScan")
        if scan_schema is not None:
            at, n = D.schema_fields(data, scan_schema)["data"]
            out.append((f"{where}-schema-scan-garbage-text", D.overwrite(data, at + 4, D.garbage_text(rng, n)),
                        "warn_or_error"))
    tf_channel = _named(data, channels, D.channel_fields, "topic", b"/tf")
    if tf_channel is not None:
        f = D.channel_fields(data, tf_channel)
        out.append((f"{where}-channel-tf-topic-length-2^31", D.put(data, f["topic"][0], "<I", 0x7FFFFFFF),
                    "warn_or_error"))
        if full:
            out.append((f"{where}-channel-tf-schema-id-999", D.put(data, f["schema_id"][0], "<H", 999), "warn_or_error"))
            eat, en = f["message_encoding"]
            out.append((f"{where}-channel-tf-encoding-garbage", D.overwrite(data, eat + 4, b"q" * en), "warn_or_error"))
    return out


def _inner_message_damage(data: bytes, inner: list[D.McapRecord], full: bool) -> list[tuple[str, bytes, str]]:
    """Lying sequence lengths inside messages of an uncompressed chunk (CDR)."""
    topics = {}
    for r in inner:
        if r.opcode == D.OP_CHANNEL:
            f = D.channel_fields(data, r)
            at, n = f["topic"]
            topics[struct.unpack_from("<H", data, r.body)[0]] = data[at + 4:at + 4 + n].decode()
    msgs = [(r, topics.get(struct.unpack_from("<H", data, r.body)[0])) for r in inner if r.opcode == D.OP_MESSAGE]
    out: list[tuple[str, bytes, str]] = []
    scans = [r for r, t in msgs if t == "/scan"]
    tfs = [r for r, t in msgs if t == "/tf"]
    if scans:
        r = scans[len(scans) // 2]
        payload = r.body + 22
        count_at = data.index(struct.pack("<I", 360), payload + 8, r.end)
        out.append(("chunk-scan-ranges-count-2^31", D.put(data, count_at, "<I", 0x7FFFFFFF), "warn_or_error"))
    if tfs:
        r = tfs[len(tfs) // 2]
        out.append(("chunk-tf-transforms-count-2^31", D.put(data, r.body + 22 + 4, "<I", 0x7FFFFFFF), "warn_or_error"))
        if full:
            out.append(("chunk-tf-message-length-2^62", D.put(data, r.offset + 1, "<Q", 1 << 62), "warn_or_error"))
            out.append(("chunk-tf-message-channel-999", D.put(data, r.body, "<H", 999), "warn_or_error"))
            frame_len_at = r.body + 22 + 4 + 4 + 8
            out.append(("chunk-tf-frame-id-length-2^31", D.put(data, frame_len_at, "<I", 0x7FFFFFFF), "warn_or_error"))
    return out


def _zero_statistics(data: bytes, rec: D.McapRecord) -> bytes:
    b = rec.body
    out = D.put(data, b, "<Q", 0)
    map_at = b + 8 + 2 + 4 * 4 + 16
    n = struct.unpack_from("<I", data, map_at)[0]
    p = map_at + 4
    while p < map_at + 4 + n:
        out = D.put(out, p + 2, "<Q", 0)
        p += 10
    return out


def _mcap_cases(B: _Builder) -> None:
    rng = random.Random(20240501)
    sources: list[tuple[str, Path, Profile, bool]] = [
        ("random", RANDOM / "sim_random_nocloud_20s.mcap", RANDOM_PROFILE, False),
        ("scene-plain", B.scene_bag("plain") / "scene_plain.mcap", SCENE, True),
    ]
    if B.full:
        sources += [("lap", LAP / "sim_lap_cloud_20s.mcap", LAP_PROFILE, False),
                    ("scene-zstd", B.scene_bag("mcap") / "scene_mcap.mcap", SCENE, False)]
        if (REAL_DIR / "nav2_turtlebot.mcap").is_file():
            sources.append(("nav2", REAL_DIR / "nav2_turtlebot.mcap", NAV2, False))
    for label, src, prof, uncompressed in sources:
        data = src.read_bytes()
        damages = _mcap_damages(data, rng, B.full, uncompressed)
        if not B.full:  # the small corpus: a representative subset
            keep = {"trunc-5", "chunk0-crc-set-zero256-at50pct", "chunk0-crc-set-flip1", "chunk0-bad-crc",
                    "chunkindex0-offset+1", "chunkindex0-usize-2^40", "chunk0-usize-2^40", "magic-broken",
                    "summary-schema-tf-garbage-text", "summary-channel-tf-topic-length-2^31", "statistics-counts-0",
                    "chunk-scan-ranges-count-2^31", "chunk-tf-transforms-count-2^31", "chunk-schema-tf-garbage-text"}
            trunc = sorted((d for d in damages if d[0].startswith("trunc-") and d[0] != "trunc-5"),
                           key=lambda d: int(d[0].split("-")[1]))
            keep |= {trunc[0][0], trunc[len(trunc) // 2][0], trunc[-1][0]}
            damages = [d for d in damages if d[0] in keep]
        pool = tuple(c for c in (*ALL_COMMANDS, "grid gt") if prof.supports(c))
        seen: set[str] = set()
        damages = [d for d in damages if not (d[0] in seen or seen.add(d[0]))]  # chunk0 may be the last chunk
        for name, damaged, expect in damages:
            path = B.file(f"mcap/{label}/{name}.mcap", damaged)
            cmds = B.rot(pool, 2, 2)
            if name.startswith("chunk-scan"):
                cmds = B.pick(("ndt-odom",), ("info", "tf echo", "map-cloud scan", "ndt-odom", "grid"))
                expect = {"info": "ok", "tf echo": "ok", "*": expect}
            elif name.startswith(("chunk0-", "chunklast-", "chunkindex", "chunk-")) and expect != "ok":
                # Damage to message data that leaves the summary intact: info describes a bag from its summary
                # (as ros2 bag info does) and need not read every chunk.
                expect = {"info": "any", "*": expect}
            B.add(f"mcap-{label}-{name}", "mcap-file", path, cmds, expect, prof)
        # The same damage inside a rosbag2 directory (metadata.yaml beside the MCAP).
        meta_src = {"random": RANDOM / "metadata.yaml", "lap": LAP / "metadata.yaml",
                    "scene-plain": B.scene_bag("plain") / "metadata.yaml",
                    "scene-zstd": B.scene_bag("mcap") / "metadata.yaml"}.get(label)
        if meta_src is None:
            continue
        as_dir = [d for d in damages if d[0] in ("chunk0-bad-crc", "magic-broken")
                  or (d[0].startswith("trunc-") and int(d[0].split("-")[1]) > 1000)][: (6 if B.full else 2)]
        for name, damaged, expect in as_dir:
            d = B.bag_dir(f"mcap-dir/{label}/{name}", meta_src.read_bytes(), src.name, damaged)
            B.add(f"mcapdir-{label}-{name}", "mcap-file", d, B.rot(pool, 1, 2), expect, prof)


# ---------------------------------------------------------------------------- metadata.yaml


def _metadata_cases(B: _Builder) -> None:
    srcs = [("scene", B.scene_bag("mcap"), SCENE)]
    if B.full:
        srcs.append(("random", RANDOM, RANDOM_PROFILE))
    rng = random.Random(7)
    for label, src, prof in srcs:
        storage = next(p for p in src.iterdir() if p.suffix == ".mcap")
        text = (src / "metadata.yaml").read_text()
        import re

        variants: list[tuple[str, bytes, str]] = [
            ("compression-zstd-file-on-plain-file",
             re.sub(r"compression_mode: .*", "compression_mode: file",
                    re.sub(r"compression_format: .*", "compression_format: zstd", text)).encode(), "warn_or_error"),
            ("message-counts-0", re.sub(r"message_count: \d+", "message_count: 0", text).encode(), "ok"),
            ("garbage-binary", bytes(rng.randrange(256) for _ in range(1500)), "warn_or_error"),
        ]
        if B.full:
            variants += [
                ("yaml-list", b"- just\n- a list\n", "warn_or_error"),
                ("truncated-half", text[: len(text) // 2].encode(), "warn_or_error"),
                ("empty", b"", "warn_or_error"),
                ("version-99", re.sub(r"version: \d+", "version: 99", text).encode(), "warn_or_error"),
                ("files-missing", text.replace(storage.name, "missing.mcap").encode(), "warn_or_error"),
                ("storage-sqlite3", re.sub(r"storage_identifier: .*", "storage_identifier: sqlite3", text).encode(),
                 "warn_or_error"),
                ("garbage-text", D.garbage_text(rng, 800), "warn_or_error"),
                ("scan-type-lie", text.replace("sensor_msgs/msg/LaserScan", "nav_msgs/msg/Odometry").encode(),
                 "warn_or_error"),
                ("message-counts-negative", re.sub(r"message_count: \d+", "message_count: -5", text).encode(),
                 "any"),
            ]
        for name, meta, expect in variants:
            d = B.bag_dir(f"metadata/{label}/{name}", meta, storage.name, storage.read_bytes())
            cmds = B.rot(tuple(c for c in (*ALL_COMMANDS, "grid gt") if prof.supports(c)))
            if name == "scan-type-lie":
                cmds = B.pick((), ("info", "ndt-odom", "grid"))
            B.add(f"metadata-{label}-{name}", "metadata", d, cmds, expect, prof)


# ---------------------------------------------------------------------------- not a bag at all


def _basic_cases(B: _Builder) -> None:
    rng = random.Random(3)
    mcap = (B.scene_bag("mcap") / "scene_mcap.mcap").read_bytes()
    items: list[tuple[str, Path, str]] = [
        ("empty-file-mcap", B.file("basic/empty.mcap", b""), "error"),
        ("not-a-bag-text", B.file("basic/notes.mcap", b"these are my notes, not a bag\n" * 20), "error"),
        ("empty-dir", _mkdir(B.inputs / "basic/empty_dir"), "error"),
        ("missing-path", B.inputs / "basic/does_not_exist", "error"),
    ]
    if B.full:
        d = _mkdir(B.inputs / "basic/dir_with_text")
        (d / "readme.txt").write_text("no bag here\n")
        d2 = _mkdir(B.inputs / "basic/metadata_only")
        (d2 / "metadata.yaml").write_bytes((B.scene_bag("mcap") / "metadata.yaml").read_bytes())
        items += [
            ("empty-file-bag", B.file("basic/empty.bag", b""), "error"),
            ("empty-file-db3", B.file("basic/empty.db3", b""), "error"),
            ("empty-file-nosuffix", B.file("basic/empty", b""), "error"),
            ("not-a-bag-random", B.file("basic/random.bag", bytes(rng.randrange(256) for _ in range(5000))), "error"),
            ("not-a-bag-png", B.file("basic/picture.db3", b"\x89PNG\r\n\x1a\n" + bytes(2000)), "error"),
            ("mcap-named-bag", B.file("basic/recording.bag", mcap), "error"),
            ("dir-with-text-only", d, "error"),
            ("dir-with-metadata-only", d2, "error"),
            ("dev-null", Path("/dev/null"), "error"),
            ("missing-in-missing-dir", B.inputs / "basic/no/such/dir/bag.mcap", "error"),
        ]
    for name, path, expect in items:
        B.add(f"basic-{name}", "not-a-bag", path, B.rot(ALL_COMMANDS, 2, 3), expect, SCENE)


def _mkdir(p: Path) -> Path:
    p.mkdir(parents=True, exist_ok=True)
    return p


# ---------------------------------------------------------------------------- sqlite3


def _sqlite_cases(B: _Builder) -> None:
    src_dir = B.scene_bag("sqlite3")
    db = next(src_dir.glob("*.db3"))
    data = db.read_bytes()
    meta = (src_dir / "metadata.yaml").read_bytes()
    page = D.sqlite_page_size(data)
    pages = len(data) // page
    rng = random.Random(11)
    variants: list[tuple[str, bytes, str]] = [
        ("trunc-half", data[: len(data) // 2], "warn_or_error"),
        ("zero-page2", D.zero_run(data, page, page), "warn_or_error"),
        ("zero-header-magic", D.zero_run(data, 0, 16), "warn_or_error"),
    ]
    if B.full:
        variants += [
            ("trunc-100", data[:100], "warn_or_error"),
            ("trunc-1page", data[:page], "warn_or_error"),
            ("trunc-minus-1page", data[: len(data) - page], "warn_or_error"),
            ("zero-page-mid", D.zero_run(data, page * (pages // 2), page), "warn_or_error"),
            ("zero-page-last", D.zero_run(data, page * (pages - 1), page), "warn_or_error"),
            ("page-size-3", D.put(data, 16, ">H", 3), "warn_or_error"),
            ("flip32-random", D.flip_bits(data, D.random_positions(rng, 100, len(data), 32)), "any"),
            ("zero-run-4096-at-60pct", D.zero_run(data, int(len(data) * 0.6), 4096), "warn_or_error"),
        ]
    for name, damaged, expect in variants:
        if damaged == data:
            continue
        d = B.bag_dir(f"sqlite/{name}", meta, db.name, damaged)
        B.add(f"sqlite-dir-{name}", "sqlite3", d, B.rot((*ALL_COMMANDS, "grid gt")), expect, SCENE)
        if B.full or name == "zero-page2":
            f = B.file(f"sqlite-bare/{name}/{db.name}", damaged)
            B.add(f"sqlite-bare-{name}", "sqlite3", f, B.rot(ALL_COMMANDS, 1, 1),
                  "error" if name == "zero-header-magic" else expect, SCENE)

    # Damage at the SQL level: rows that lie.
    def sql_variant(name: str, statements: list[str]) -> Path:
        d = B.bag_dir(f"sqlite-sql/{name}", meta, db.name, data)
        con = sqlite3.connect(d / db.name)
        for st in statements:
            con.execute(st)
        con.commit()
        con.close()
        return d

    scan_topic = "(SELECT id FROM topics WHERE name = '/scan')"
    tf_topic = "(SELECT id FROM topics WHERE name = '/tf')"
    scan_cmds = B.pick(("grid",), ("info", "tf echo", "map-cloud scan", "ndt-odom", "grid"))
    d = sql_variant("scan-blob-garbage", [f"UPDATE messages SET data = X'000100' WHERE id = (SELECT id FROM messages "
                                          f"WHERE topic_id = {scan_topic} LIMIT 1 OFFSET 5)"])
    B.add("sqlite-sql-scan-blob-garbage", "sqlite3", d, scan_cmds,
          {"info": "ok", "tf echo": "ok", "*": "warn_or_error"}, SCENE)
    d = sql_variant("tf-blob-garbage", [f"UPDATE messages SET data = X'00010000ffffff7f' WHERE id = (SELECT id FROM "
                                        f"messages WHERE topic_id = {tf_topic} LIMIT 1 OFFSET 40)"])
    B.add("sqlite-sql-tf-blob-garbage", "sqlite3", d, B.pick(("tf echo",), ("info", "tf frames", "tf echo", "grid")),
          {"info": "any", "*": "warn_or_error"}, SCENE)
    if B.full:
        d = sql_variant("scan-type-unknown", ["UPDATE topics SET type = 'garbage_msgs/msg/Nope' WHERE name = '/scan'"])
        B.add("sqlite-sql-scan-type-unknown", "sqlite3", d, ("info", "tf echo", "ndt-odom", "grid"),
              {"info": "any", "tf echo": "any", "*": "warn_or_error"}, SCENE)
        d = sql_variant("scan-rows-dangling-topic", [f"UPDATE messages SET topic_id = 999 WHERE topic_id = {scan_topic} "
                                                    "AND id % 3 = 0"])
        B.add("sqlite-sql-scan-rows-dangling-topic", "sqlite3", d, ("info", "ndt-odom", "grid"), "any", SCENE)
        d = sql_variant("topics-table-dropped", ["DROP TABLE topics"])
        B.add("sqlite-sql-topics-table-dropped", "sqlite3", d, ("info", "tf echo", "grid"), "warn_or_error", SCENE)
        d = sql_variant("no-rosbag-tables", ["DROP TABLE messages", "DROP TABLE topics"])
        B.add("sqlite-sql-no-rosbag-tables", "sqlite3", d, ("info", "tf echo"), "warn_or_error", SCENE)
        d = sql_variant("scan-blob-empty", [f"UPDATE messages SET data = X'' WHERE topic_id = {scan_topic}"])
        B.add("sqlite-sql-scan-blob-empty", "sqlite3", d, ("ndt-odom", "grid", "map-cloud scan"), "warn_or_error", SCENE)


# ---------------------------------------------------------------------------- ROS 1


def _ros1_damages(data: bytes, rng: random.Random, full: bool, synthetic: bool) -> list[tuple[str, bytes, str]]:
    recs = D.ros1_layout(data)
    out: list[tuple[str, bytes, str]] = []
    bag_header = next(r for r in recs if r.op == 0x03)
    chunks = [r for r in recs if r.op == 0x05]
    c0 = chunks[0]
    conns_at_end = [r for r in recs if r.op == 0x07]
    offsets = {100, c0.data_at + c0.data_len // 2}
    if full:
        offsets |= {13, 20, c0.offset, c0.offset + 30, c0.data_at, c0.data_at + 10, c0.end - 1, c0.end + 20,
                    conns_at_end[0].offset if conns_at_end else len(data) - 50, len(data) - 10, len(data) - 1}
        offsets |= {rng.randrange(14, len(data)) for _ in range(4)}
    for n in sorted(o for o in offsets if 0 < o < len(data)):
        out.append((f"trunc-{n}", data[:n], "error" if n < 13 else "warn_or_error"))
    out.append(("chunk0-header-len-2^31", D.put(data, c0.offset, "<I", 0x7FFFFFFF), "warn_or_error"))
    out.append(("zero4096-mid-chunk0", D.zero_run(data, c0.data_at + c0.data_len // 3, 4096), "warn_or_error"))
    out.append(("index-pos-0", D.put(data, D.ros1_field_value_at(bag_header, "index_pos"), "<Q", 0), "warn_or_error"))
    if full:
        out += [
            ("index-pos-2^62", D.put(data, D.ros1_field_value_at(bag_header, "index_pos"), "<Q", 1 << 62), "warn_or_error"),
            ("index-pos-past-eof", D.put(data, D.ros1_field_value_at(bag_header, "index_pos"), "<Q", len(data) + 100),
             "warn_or_error"),
            ("conn-count-2^31", D.put(data, D.ros1_field_value_at(bag_header, "conn_count"), "<I", 0x7FFFFFFF),
             "warn_or_error"),
            ("chunk-count-2^31", D.put(data, D.ros1_field_value_at(bag_header, "chunk_count"), "<I", 0x7FFFFFFF),
             "warn_or_error"),
            ("chunk0-data-len-2^31", D.put(data, c0.data_len_at, "<I", 0x7FFFFFFF), "warn_or_error"),
            # The uncompressed size of an uncompressed chunk: nothing needs it.
            ("chunk0-size-2^32-1", D.put(data, D.ros1_field_value_at(c0, "size"), "<I", 0xFFFFFFFF), "any"),
            ("chunk0-field-length-2^31", D.put(data, c0.fields["compression"][0], "<I", 0x7FFFFFF0), "warn_or_error"),
            ("flip16-random", D.flip_bits(data, D.random_positions(rng, 13, len(data), 16)), "any"),
        ]
        # The /scan connection (or /tf, in a bag without scans) in the index section.
        by_topic = {}
        for conn in conns_at_end:
            tat, tn = conn.fields.get("topic", (None, 0))
            if tat is not None:
                by_topic[data[tat + 4 + 6:tat + 4 + tn].decode("latin-1")] = conn
        conn = by_topic.get("/scan") or by_topic.get("/tf")
        if conn is not None:
            label = "scan" if conn is by_topic.get("/scan") else "tf"
            tat = data.find(b"type=", conn.data_at, conn.end)
            if tat > 0:
                out.append((f"{label}-conn-type-garbage", D.overwrite(data, tat + 5, b"garbage_x/"), "warn_or_error"))
            mat = data.find(b"message_definition=", conn.data_at, conn.end)
            if mat > 0:
                out.append((f"{label}-conn-msgdef-garbage", D.overwrite(data, mat + 19, D.garbage_text(rng, 40)),
                            "warn_or_error"))
    if synthetic:
        inner = _ros1_inner(data, c0)
        scan = inner.get("/scan")
        if scan is not None:
            count_at = data.index(struct.pack("<I", 360), scan.data_at + 12, scan.end)
            out.append(("scan-ranges-count-2^31", D.put(data, count_at, "<I", 0x7FFFFFFF), "warn_or_error"))
        tf = inner.get("/tf")
        if tf is not None and full:
            out.append(("tf-transforms-count-2^31", D.put(data, tf.data_at, "<I", 0x7FFFFFFF), "warn_or_error"))
    return [d for d in out if d[1] != data]


def _ros1_inner(data: bytes, chunk: D.Ros1Record) -> dict[str, D.Ros1Record]:
    """A message record from the middle of ``chunk`` for each topic (uncompressed chunks only)."""
    sub = D.ROS1_MAGIC + data[chunk.data_at:chunk.end]
    shift = chunk.data_at - len(D.ROS1_MAGIC)
    recs = D.ros1_layout(sub)
    topic_of: dict[int, str] = {}
    by_topic: dict[str, list[D.Ros1Record]] = {}
    for r in recs:
        conn_at = r.fields.get("conn")
        if conn_at is None:
            continue
        conn = struct.unpack_from("<I", sub, conn_at[0] + 4 + 5)[0]
        if r.op == 0x07:
            tat, tn = r.fields["topic"]
            topic_of[conn] = sub[tat + 4 + 6:tat + 4 + tn].decode()
        elif r.op == 0x02 and conn in topic_of:
            moved = D.Ros1Record(r.offset + shift, r.op, r.header_len, r.data_len,
                                 {k: (p + shift, n) for k, (p, n) in r.fields.items()})
            by_topic.setdefault(topic_of[conn], []).append(moved)
    return {t: rs[len(rs) // 2] for t, rs in by_topic.items()}


def _ros1_cases(B: _Builder) -> None:
    rng = random.Random(99)
    sources = [("scene", B.scene_bag("ros1"), SCENE, True)]
    if (REAL_DIR / "tf_example.bag").is_file():
        sources.append(("tf_example", REAL_DIR / "tf_example.bag", TF_EXAMPLE, False))
    if B.full and (REAL_DIR / "turtlebot3_real_lidar_odom.bag").is_file():
        sources.append(("turtlebot3", REAL_DIR / "turtlebot3_real_lidar_odom.bag", TURTLEBOT3, False))
    for label, src, prof, synthetic in sources:
        damages = _ros1_damages(src.read_bytes(), rng, B.full, synthetic)
        if not B.full:
            keep = {"chunk0-header-len-2^31", "zero4096-mid-chunk0", "index-pos-0", "scan-ranges-count-2^31"}
            keep |= {d[0] for d in damages if d[0].startswith("trunc-")}
            if label == "tf_example":
                keep = {"chunk0-header-len-2^31", "index-pos-0"} | {d[0] for d in damages if d[0].startswith("trunc-")}
            damages = [d for d in damages if d[0] in keep]
        pool = tuple(c for c in (*ALL_COMMANDS, "grid gt") if prof.supports(c))
        for name, damaged, expect in damages:
            path = B.file(f"ros1/{label}/{name}.bag", damaged)
            cmds = B.rot(pool, 1, 2)
            if name.startswith("scan-"):
                cmds = B.pick(("grid",), ("info", "tf echo", "map-cloud scan", "ndt-odom", "grid"))
                # a lying ranges count: only scan readers meet it; a damaged /scan connection: others may refuse
                other = "any" if name.startswith("scan-conn") else "ok"
                expect = {"info": other, "tf echo": other, "*": expect}
            B.add(f"ros1-{label}-{name}", "ros1", path, cmds, expect, prof)


# ---------------------------------------------------------------------------- message content


SCAN_CMDS = ("map-cloud scan", "ndt-odom", "grid", "slam")
TF_VALUE_CMDS = ("tf echo", "tf point", "map-cloud", "ndt-odom", "grid")


def _content_cases(B: _Builder) -> None:
    scene = B.scene
    full = B.full

    def add(name: str, sc: Scene, consumers: tuple[str, ...], expect: str, others: tuple[str, ...] = (),
            others_expect: str = "ok", small: bool = False, extra_runs: Callable[[Path], list[Run]] | None = None,
            note: str = "") -> None:
        if not (full or small):
            return
        path = B.write_scene(f"content/{name}", sc)
        cmds = consumers + others if full else B.rot(consumers, 2)
        exp = {c: expect for c in consumers}
        exp["*"] = others_expect
        case = B.add(f"content-{name}", "message-content", path, cmds, exp, SCENE, note=note)
        for run in case.runs:  # tf echo at the tf rate, so that it meets every sample (default: 1 Hz)
            if run.command == "tf echo":
                run.argv += ["--rate", "20"]
        if extra_runs is not None:
            case.runs += extra_runs(path)

    # LaserScan ----------------------------------------------------------------
    def set_(**values):
        def fn(item):
            for k, v in values.items():
                setattr(item, k, v)
        return fn

    add("scan-increment-nan-one", edit(scene, "/scan", set_(angle_increment=math.nan)), SCAN_CMDS, "warn_or_error",
        ("info",), small=True)
    add("scan-increment-nan-all", edit(scene, "/scan", set_(angle_increment=math.nan), "all"), SCAN_CMDS,
        "warn_or_error", ("info",))
    add("scan-increment-zero-all", edit(scene, "/scan", set_(angle_increment=0.0), "all"), SCAN_CMDS, "warn_or_error",
        ("info", "tf echo"), small=True)
    add("scan-increment-zero-one", edit(scene, "/scan", set_(angle_increment=0.0)), SCAN_CMDS, "warn_or_error")

    def wrong_sign(s: Scan) -> None:
        s.angle_increment = -s.angle_increment
    add("scan-increment-wrong-sign-all", edit(scene, "/scan", wrong_sign, "all"), SCAN_CMDS, "warn_or_error",
        small=True)

    def reversed_scan(s: Scan) -> None:  # an upside-down lidar: consistent negative increment, valid
        s.angle_min, s.angle_max, s.angle_increment = s.angle_max, s.angle_min, -s.angle_increment
        s.ranges = s.ranges[::-1].copy()
    add("scan-reversed-consistent", edit(scene, "/scan", reversed_scan, "all"), SCAN_CMDS, "ok",
        note="a scan with angle_min > angle_max and a negative increment is valid (REP 117)")
    add("scan-angle-min-inf-one", edit(scene, "/scan", set_(angle_min=math.inf)), SCAN_CMDS, "warn_or_error",
        small=True)
    add("scan-angle-min-inf-all", edit(scene, "/scan", set_(angle_min=math.inf), "all"), SCAN_CMDS, "warn_or_error")

    def ranges_at(value: float, every: int = 7):
        def fn(s: Scan) -> None:
            r = s.ranges.copy()
            r[::every] = value
            s.ranges = r
        return fn
    add("scan-ranges-1e30-normal-max", edit(scene, "/scan", ranges_at(1e30), "all"), SCAN_CMDS, "ok",
        note="returns beyond range_max are ordinary invalid readings")

    def max_and_ranges(range_max: float, value: float):
        def fn(s: Scan) -> None:
            s.range_max = range_max
            ranges_at(value)(s)
        return fn
    add("scan-range-max-1e30-ranges-1e30", edit(scene, "/scan", max_and_ranges(1e30, 1e30)), SCAN_CMDS,
        "warn_or_error", small=True)
    add("scan-range-max-1e30-ranges-1e30-all", edit(scene, "/scan", max_and_ranges(1e30, 1e30), "all"), SCAN_CMDS,
        "warn_or_error")
    add("scan-range-max-inf-ranges-inf", edit(scene, "/scan", max_and_ranges(math.inf, math.inf), "all"), ("grid",),
        "warn_or_error", ("map-cloud scan", "ndt-odom"), "any",
        note="inf returns are invalid anyway; range_max bounds only grid's free-space rays")
    add("scan-range-max-inf-ranges-3e38", edit(scene, "/scan", max_and_ranges(math.inf, 3e38)), SCAN_CMDS,
        "warn_or_error")

    def negative_ranges(s: Scan) -> None:
        s.range_min = -1.0
        r = s.ranges.copy()
        r[::5] = -0.5
        s.ranges = r
    add("scan-negative-ranges-negative-min", edit(scene, "/scan", negative_ranges, "all"), SCAN_CMDS, "warn_or_error",
        small=True)
    add("scan-all-nan", edit(scene, "/scan", ranges_at(math.nan, 1), "all"), SCAN_CMDS, "warn_or_error",
        ("info", "tf echo", "tf point"), small=True)
    add("scan-one-all-nan", edit(scene, "/scan", ranges_at(math.nan, 1)), SCAN_CMDS, "ok",
        note="one scan without a single return is odd but valid")

    def empty(s: Scan) -> None:
        s.ranges = np.zeros(0, dtype=np.float32)
    add("scan-empty-all", edit(scene, "/scan", empty, "all"), SCAN_CMDS, "warn_or_error", small=True)
    add("scan-empty-one", edit(scene, "/scan", empty), SCAN_CMDS, "warn_or_error")

    def short(s: Scan) -> None:
        s.ranges = s.ranges[:100].copy()
    add("scan-count-disagrees-with-angles", edit(scene, "/scan", short, "all"), SCAN_CMDS, "warn_or_error")
    add("scan-range-min-nan", edit(scene, "/scan", set_(range_min=math.nan), "all"), SCAN_CMDS, "warn_or_error")

    # PointCloud2 --------------------------------------------------------------
    def cloud_over(**overrides):
        def fn(c: Cloud) -> None:
            c.overrides.update(overrides)
        return fn

    first_cloud = scene.of("/camera/depth/points")[0].item
    n = first_cloud.xyz.shape[0]
    add("cloud-point-step-smaller-than-fields", edit(scene, "/camera/depth/points",
                                                     cloud_over(point_step=8, row_step=8 * n)),
        ("map-cloud",), "warn_or_error", ("info", "tf echo"), small=True)
    add("cloud-field-offset-past-point-step", edit(scene, "/camera/depth/points", cloud_over(
        fields=[("x", 0, 7, 1), ("y", 4, 7, 1), ("z", 100, 7, 1)])), ("map-cloud",), "warn_or_error", small=True)
    add("cloud-bigendian-flag-on-little-endian-data", edit(scene, "/camera/depth/points", cloud_over(is_bigendian=True)),
        ("map-cloud",), "warn_or_error", small=True,
        note="byte-swapped float32 of metric coordinates are absurd values (e.g. 1e-38 or 1e+20)")

    def far_points(c: Cloud) -> None:
        xyz = c.xyz.copy()
        xyz[::10] = 1e30
        c.xyz = xyz
    add("cloud-coordinates-1e30", edit(scene, "/camera/depth/points", far_points), ("map-cloud",), "warn_or_error",
        small=True)
    add("cloud-coordinates-1e30-all-clouds", edit(scene, "/camera/depth/points", far_points, "all"), ("map-cloud",),
        "warn_or_error")
    add("cloud-width-lie-2^26", edit(scene, "/camera/depth/points", cloud_over(width=1 << 26, row_step=(1 << 26) * 16)),
        ("map-cloud",), "warn_or_error", small=True)
    add("cloud-height-width-lie-65535^2", edit(scene, "/camera/depth/points", cloud_over(
        height=65535, width=65535, row_step=65535 * 16)), ("map-cloud",), "warn_or_error", small=True)
    add("cloud-row-step-lie", edit(scene, "/camera/depth/points", cloud_over(row_step=0xFFFFFFF0)), ("map-cloud",),
        "warn_or_error")
    add("cloud-point-step-zero", edit(scene, "/camera/depth/points", cloud_over(point_step=0, row_step=0)),
        ("map-cloud",), "warn_or_error")
    add("cloud-point-step-2^31", edit(scene, "/camera/depth/points", cloud_over(point_step=1 << 31, row_step=0xFFFFFFFF)),
        ("map-cloud",), "warn_or_error")
    add("cloud-datatype-unknown", edit(scene, "/camera/depth/points", cloud_over(
        fields=[("x", 0, 7, 1), ("y", 4, 99, 1), ("z", 8, 7, 1)])), ("map-cloud",), "warn_or_error")
    add("cloud-no-z-field", edit(scene, "/camera/depth/points", cloud_over(fields=[("x", 0, 7, 1), ("y", 4, 7, 1)])),
        ("map-cloud",), "warn_or_error")

    def empty_cloud(c: Cloud) -> None:
        c.xyz = np.zeros((0, 3))
    add("cloud-empty-one", edit(scene, "/camera/depth/points", empty_cloud), ("map-cloud",), "ok")

    def nan_cloud(c: Cloud) -> None:
        c.xyz = np.full_like(c.xyz, np.nan)
    add("cloud-all-nan-one", edit(scene, "/camera/depth/points", nan_cloud), ("map-cloud",), "ok",
        note="NaN points are dropped by design")

    # tf values -----------------------------------------------------------------
    def odom_tf(fn, index: int = 50):
        """Damage odom->base_link sample ``index`` (50: t = 2.5 s, the stamp of a scan and of a cloud)."""
        def apply(entries_scene: Scene) -> Scene:
            out = entries_scene.copy()
            tfs = [e for e in out.of("/tf") if e.item[0].child == "base_link"]
            fn(tfs[index].item[0])
            return out
        return apply

    def set_xyz(x=None, y=None, z=None):
        def fn(tf: Tf) -> None:
            xyz = list(tf.xyz)
            for i, v in enumerate((x, y, z)):
                if v is not None:
                    xyz[i] = v
            tf.xyz = tuple(xyz)
        return fn

    def set_q(q):
        def fn(tf: Tf) -> None:
            tf.quat_xyzw = q
        return fn

    add("tf-translation-1e30", odom_tf(set_xyz(x=1e30))(scene), TF_VALUE_CMDS, "warn_or_error", ("info", "tf frames"),
        small=True)
    add("tf-translation-nan", odom_tf(set_xyz(y=math.nan))(scene), TF_VALUE_CMDS, "warn_or_error",
        ("info", "tf frames"), small=True)
    add("tf-quaternion-zero", odom_tf(set_q((0.0, 0.0, 0.0, 0.0)))(scene), TF_VALUE_CMDS, "warn_or_error",
        ("info", "tf frames"), small=True)
    add("tf-quaternion-nan", odom_tf(set_q((0.0, 0.0, math.nan, 1.0)))(scene), TF_VALUE_CMDS, "warn_or_error")
    add("tf-quaternion-not-unit-2", odom_tf(set_q((0.0, 0.0, 0.0, 2.0)))(scene), TF_VALUE_CMDS, "warn_or_error")
    add("tf-translation-inf", odom_tf(set_xyz(z=math.inf))(scene), TF_VALUE_CMDS, "warn_or_error")

    def glitch_zero(tf: Tf) -> None:
        i = int(np.argmax(np.abs(tf.xyz[:2])))
        set_xyz(**{"xy"[i]: 0.0})(tf)
    add("tf-glitch-one-coordinate-zeroed", odom_tf(glitch_zero)(scene), TF_VALUE_CMDS, "warn_or_error", small=True,
        note="odom->base_link jumps ~0.8 m for one 50 ms sample and back")

    def yaw_flip(tf: Tf) -> None:
        x, y, z, w = tf.quat_xyzw
        yaw = 2 * math.atan2(z, w) + math.radians(170)
        tf.quat_xyzw = yaw_quat(yaw)
    add("tf-glitch-yaw-flipped-170deg", odom_tf(yaw_flip)(scene), TF_VALUE_CMDS, "warn_or_error", small=True)

    def conflicting_duplicate(sc: Scene) -> Scene:
        out = sc.copy()
        tfs = [e for e in out.of("/tf") if e.item[0].child == "base_link"]
        orig = tfs[50]
        tf = Tf(orig.item[0].stamp_ns, "odom", "base_link", (orig.item[0].xyz[0] + 1.0, orig.item[0].xyz[1] - 0.5, 0.0),
                yaw_quat(1.0))
        out.entries.append(type(orig)("/tf", orig.log_ns + 100, [tf]))
        return out
    add("tf-same-stamp-conflicting-values", conflicting_duplicate(scene), TF_VALUE_CMDS, "warn_or_error", ("info",),
        small=True)

    def two_publishers(sc: Scene) -> Scene:
        out = sc.copy()
        entry_type = type(out.entries[0])
        rng = np.random.default_rng(5)
        for i in range(int(6.0 * 200)):
            stamp = T0 + i * 5_000_000 + 1_000
            xyz = tuple(float(v) for v in rng.normal(0.0, 1e-3, 3))
            out.entries.append(entry_type("/tf", stamp + 500_000, [Tf(stamp, "odom", "base_link", xyz, (0, 0, 0, 1))]))
        return out
    add("tf-two-publishers-one-edge", two_publishers(scene), TF_VALUE_CMDS, "warn_or_error", ("info", "tf frames"),
        small=True, note="odom->base_link at 20 Hz from the moving robot and at 200 Hz near zero from another node")

    def stray_stamp(tf: Tf) -> None:
        tf.stamp_ns = 1
    add("tf-stray-stamp-1ns", odom_tf(stray_stamp)(scene), TF_VALUE_CMDS + ("info", "tf frames"), "warn_or_error",
        small=True, note="one odom->base_link sample stamped 1 ns among 121 stamps: time ranges span 53 years")

    def backwards(sc: Scene) -> Scene:
        out = sc.copy()
        for e in out.of("/tf"):
            for tf in e.item:
                if tf.stamp_ns > T0 + 3 * S:
                    tf.stamp_ns -= 3 * S + 500_000_000
        return out
    add("tf-time-goes-backwards", backwards(scene), TF_VALUE_CMDS + ("tf frames",), "warn_or_error", ("info",),
        small=True, note="the tf clock jumps back 3.5 s half way (a restarted sim clock), other topics do not")

    def two_parents(sc: Scene) -> Scene:
        out = sc.copy()
        entry_type = type(out.entries[0])
        for e in list(out.of("/tf")):
            tf = e.item[0]
            if tf.child == "base_link" and (tf.stamp_ns // (S // 20)) % 2 == 0:
                out.entries.append(entry_type("/tf", e.log_ns + 10, [Tf(tf.stamp_ns + 1000, "odom_alt", "base_link",
                                                                       (0.0, 0.0, 0.0), (0, 0, 0, 1))]))
        return out
    add("tf-frame-with-two-parents", two_parents(scene), TF_VALUE_CMDS + ("info", "tf frames"), "warn_or_error",
        small=True)

    def loop(sc: Scene) -> Scene:
        out = sc.copy()
        out.entries[0].item.append(Tf(T0, "camera_link", "odom", (0, 0, 0), (0, 0, 0, 1)))
        return out
    add("tf-loop", loop(scene), TF_VALUE_CMDS + ("info", "tf frames"), "warn_or_error")

    def deep_chain(sc: Scene) -> Scene:
        out = sc.copy()
        parent = "base_link"
        for i in range(3000):
            out.entries[0].item.append(Tf(T0, parent, f"link_{i}", (0.001, 0, 0), (0, 0, 0, 1)))
            parent = f"link_{i}"
        return out

    def deep_runs(path: Path) -> list[Run]:
        out = B.out_dir("content-tf-static-chain-3000-deep", "tf point deep")
        return [Run("tf echo deep", ["tf", "echo", str(path), "map", "link_2999"], "ok", names=(str(path),)),
                Run("tf point deep", ["tf", "point", str(path), "--out", str(out), "--point", "1", "0", "0", "--frame",
                                      "link_2999", "--targets", "map,odom", "--force"], "ok", watch=out,
                    prefill=B.prefilled("tf point"), own=OWN_OUTPUTS["tf point"], names=(str(path),))]
    add("tf-static-chain-3000-deep", deep_chain(scene), ("info", "tf frames", "tf echo"), "ok",
        ("map-cloud", "grid"), small=True, extra_runs=deep_runs)

    def static_nan(sc: Scene) -> Scene:
        out = sc.copy()
        out.entries[0].item[0].xyz = (math.nan, 0.0, 0.2)
        return out
    add("tf-static-scan-mount-nan", static_nan(scene), ("map-cloud scan", "ndt-odom", "grid"), "warn_or_error",
        ("tf echo",))

    # ground truth and odometry ------------------------------------------------------
    def gt(fn, which="one"):
        if which == "all":
            return edit(scene, "/ground_truth", fn, which)
        out = scene.copy()
        fn(out.of("/ground_truth")[50].item)  # t = 2.5 s, the stamp of a scan
        return out

    def odom_xyz(value):
        def fn(o: Odom) -> None:
            o.xyz = (value, o.xyz[1], o.xyz[2])
        return fn

    def odom_q(q):
        def fn(o: Odom) -> None:
            o.quat_xyzw = q
        return fn
    add("ground-truth-nan", gt(odom_xyz(math.nan)), ("grid gt", "ndt-odom"), "warn_or_error", ("grid",), small=True)
    add("ground-truth-quaternion-zero", gt(odom_q((0.0, 0.0, 0.0, 0.0))), ("grid gt", "ndt-odom"), "warn_or_error",
        ("grid",), small=True)
    add("ground-truth-nan-all", gt(odom_xyz(math.nan), "all"), ("grid gt", "ndt-odom"), "warn_or_error")
    add("ground-truth-1e30", gt(odom_xyz(1e30)), ("grid gt", "ndt-odom"), "warn_or_error")

    # /odom is ndt-odom's odometry only when tf has no odom -> base_link: a bag with wheel odometry on /odom only.
    odom_only = scene.copy()
    odom_only.entries = [e for e in odom_only.entries if not (e.topic == "/tf" and e.item[0].child == "base_link")]

    def odom_sample(fn):
        out = odom_only.copy()
        fn(out.of("/odom")[50].item)  # t = 2.5 s, the stamp of a scan
        return out
    add("odom-only-valid", odom_only, ("ndt-odom",), "ok", small=False)
    add("odom-only-nan", odom_sample(odom_xyz(math.nan)), ("ndt-odom",), "warn_or_error")
    add("odom-only-quaternion-zero", odom_sample(odom_q((0.0, 0.0, 0.0, 0.0))), ("ndt-odom",), "warn_or_error")
    add("odom-only-1e30", odom_sample(odom_xyz(1e30)), ("ndt-odom",), "warn_or_error")


# ---------------------------------------------------------------------------- option values


def _option_cases(B: _Builder) -> None:
    bag = B.scene_bag("mcap")
    b = str(bag)
    full = B.full

    def opt(name: str, command: str, extra: list[str], expect: str, names: tuple[str, ...], small: bool = False,
            prof: Profile = SCENE) -> None:
        if not (full or small):
            return
        run = B.std_run(f"option-{name}", command, bag, prof, expect, names=names, extra=extra)
        B.add_runs(f"option-{name}", "option-value", bag, [run])

    opt("voxel-1e-9", "map-cloud", ["--voxel", "1e-9"], "warn_or_error", ("voxel", "1e-09", "1e-9"), small=True)
    opt("voxel-nan", "map-cloud", ["--voxel", "nan"], "error", ("voxel", "nan"), small=True)
    opt("voxel-inf", "map-cloud", ["--voxel", "inf"], "error", ("voxel", "inf"), small=True)
    opt("voxel-negative", "map-cloud", ["--voxel", "-1"], "error", ("voxel", "-1"))
    opt("seed-negative", "map-cloud", ["--seed", "-5"], "any", ("seed", "-5"), small=True)
    opt("sample-nan", "map-cloud", ["--sample", "nan"], "error", ("sample", "nan"))
    opt("sample-2", "map-cloud", ["--sample", "2"], "error", ("sample", "2"))
    opt("max-range-nan", "map-cloud", ["--max-range", "nan"], "error", ("max-range", "max_range", "nan"))
    opt("map-cloud-stamp-unknown-choice", "map-cloud", ["--stamp", "foo"], "error", ("stamp", "foo"), small=True)
    opt("cell-size-1e-4", "ndt-odom", ["--cell-size", "1e-4"], "warn_or_error", ("cell-size", "cell_size", "0.0001"),
        small=True)
    opt("cell-size-nan", "ndt-odom", ["--cell-size", "nan"], "error", ("cell-size", "nan"))
    opt("min-score-nan", "ndt-odom", ["--min-score", "nan"], "error", ("min-score", "nan"))
    opt("scan-frame-offset-nan", "ndt-odom", ["--scan-frame-offset", "nan,0,0"], "error",
        ("scan-frame-offset", "nan"))
    opt("echo-rate-1e9", "tf echo", ["--rate", "1e9"], "warn_or_error", ("rate", "1e+09", "1e9"), small=True)
    opt("echo-rate-nan", "tf echo", ["--rate", "nan"], "error", ("rate", "nan"))
    opt("echo-rate-inf", "tf echo", ["--rate", "inf"], "error", ("rate", "inf"))
    opt("echo-rate-abc", "tf echo", ["--rate", "abc"], "error", ("rate", "abc"), small=True)
    opt("point-rate-1e7", "tf point", ["--rate", "1e7"], "warn_or_error", ("rate", "1e+07", "1e7"), small=True)
    opt("point-rate-1e-12", "tf point", ["--rate", "1e-12"], "any", ("rate",))
    opt("grid-resolution-1e-9", "grid", ["--resolution", "1e-9"], "warn_or_error", ("resolution", "1e-09"), small=True)
    opt("grid-resolution-1e9", "grid", ["--resolution", "1e9"], "warn_or_error", ("resolution", "1e+09", "1e9"))
    opt("grid-resolution-nan", "grid", ["--resolution", "nan"], "error", ("resolution", "nan"))
    opt("grid-resolution-0", "grid", ["--resolution", "0"], "error", ("resolution",))
    opt("grid-max-range-nan", "grid", ["--max-range", "nan"], "error", ("max-range", "nan"))
    opt("grid-max-range-negative", "grid", ["--max-range", "-1"], "error", ("max-range", "-1"))
    opt("grid-poses-unknown-word", "grid", ["--poses", "groundtruth"], "error", ("groundtruth",))

    # tf point --point nan 0 0 (the standard run passes --point 1 0 0 first; click keeps the last)
    if True:
        out = B.out_dir("option-point-nan", "tf point")
        B.add_runs("option-point-nan", "option-value", bag, [Run(
            "tf point", ["tf", "point", b, "--out", str(out), "--point", "nan", "0", "0", "--frame", "map", "--force"],
            "error", watch=out, prefill=B.prefilled("tf point"), own=OWN_OUTPUTS["tf point"], names=("point", "nan"))])
    if full:
        out = B.out_dir("option-point-inf", "tf point")
        B.add_runs("option-point-inf", "option-value", bag, [Run(
            "tf point", ["tf", "point", b, "--out", str(out), "--point", "inf", "0", "0", "--frame", "map", "--force"],
            "error", watch=out, prefill=B.prefilled("tf point"), own=OWN_OUTPUTS["tf point"], names=("point", "inf"))])
    B.add_runs("option-unknown-command", "option-value", None,
               [Run("(unknown)", ["frobnicate", b], "error", names=("frobnicate",))])
    if full:
        B.add_runs("option-missing-out", "option-value", bag, [Run("grid", ["grid", b], "error", names=("--out", "out"))])
        B.add_runs("option-unknown-option", "option-value", bag,
                   [Run("info", ["info", b, "--frobnicate"], "error", names=("frobnicate",))])
        for name, extra, expect, names in (
                ("simulate-duration-nan", ["--duration", "nan"], "error", ("duration", "nan")),
                ("simulate-duration-negative", ["--duration", "-1"], "error", ("duration", "-1")),
                ("simulate-duration-1e9", ["--duration", "1e9"], "warn_or_error", ("duration", "1e+09", "1e9")),
                ("simulate-cloud-size-huge", ["--duration", "1", "--cloud-size", "100000x100000"], "warn_or_error",
                 ("cloud-size", "100000")),
                ("simulate-seed-negative", ["--duration", "1", "--no-cloud", "--seed", "-5"], "any", ("seed", "-5")),
                ("simulate-cloud-rate-inf", ["--duration", "1", "--cloud-rate", "inf"], "error", ("cloud-rate", "inf")),
        ):
            parent = B.out_dir(f"option-{name}", "simulate")
            target = parent / "sim"
            B.add_runs(f"option-{name}", "option-value", None, [Run(
                "simulate", ["simulate", str(target), *extra], expect, watch=parent, prefill=dict(USER_FILES),
                own=("sim",), names=names)])

    # TUM trajectories for grid --poses
    rows = []
    for e in B.scene.of("/ground_truth"):
        o = e.item
        rows.append((o.stamp_ns, *o.xyz, *o.quat_xyzw))

    def tum(rows_: list[tuple]) -> bytes:
        lines = []
        for stamp, *vals in rows_:
            lines.append(f"{stamp // S}.{stamp % S:09d} " + " ".join(repr(float(v)) for v in vals))
        return ("\n".join(lines) + "\n").encode()

    def with_row(i: int, **changes) -> list[tuple]:
        out = [list(r) for r in rows]
        for k, v in changes.items():
            out[i][{"x": 1, "y": 2, "z": 3, "qx": 4, "qy": 5, "qz": 6, "qw": 7}[k]] = v
        return [tuple(r) for r in out]

    mid = len(rows) // 2
    tums: list[tuple[str, bytes, str, bool]] = [
        ("valid", tum(rows), "ok", True),
        ("position-nan", tum(with_row(mid, x=math.nan)), "warn_or_error", True),
        ("position-1e30", tum(with_row(mid, y=1e30)), "warn_or_error", True),
        ("stamp-1e30", tum(rows).replace(f"{rows[mid][0] // S}.".encode(), b"1000000000000000000000000000000.", 1),
         "warn_or_error", True),
        ("garbage-text", b"this is not a trajectory\n\x00\x01\x02 garbage\n", "error", True),
        ("position-inf", tum(with_row(mid, x=math.inf)), "warn_or_error", False),
        ("quaternion-nan", tum(with_row(mid, qz=math.nan)), "warn_or_error", False),
        ("all-positions-nan", tum([(r[0], math.nan, math.nan, math.nan, *r[4:]) for r in rows]), "warn_or_error", False),
        ("empty", b"", "error", False),
        ("only-comments", b"# stamp x y z qx qy qz qw\n", "error", False),
        ("binary", bytes(range(256)) * 4, "error", False),
        ("stamps-outside-bag", tum([(r[0] + 1000 * S, *r[1:]) for r in rows]), "warn_or_error", False),
        ("stamps-duplicate-conflicting", tum(rows + [(rows[mid][0], 5.0, 5.0, 0.0, 0.0, 0.0, 0.0, 1.0)]),
         "warn_or_error", False),
        ("stamp-exponent-notation", tum(rows).replace(f"{rows[mid][0] // S}.".encode(), b"1.7e9 ", 1)
         .replace(b"1.7e9 " + f"{rows[mid][0] % S:09d}".encode(), b"1.7e9", 1), "any", False),
    ]
    for name, content, expect, small in tums:
        if not (full or small):
            continue
        path = B.file(f"tum/{name}.tum", content)
        # A file whose lines are wrong must be named; when it does not fit the bag, naming either is fair.
        names = (str(path), b) if name == "stamps-outside-bag" else (str(path),)
        run = B.std_run(f"tum-{name}", "grid", bag, SCENE, expect, names=names,
                        extra=["--poses", str(path), "--base-frame", "base_link"], label="grid tum")
        B.add_runs(f"tum-{name}", "tum-file", path, [run])
    if full:
        d = _mkdir(B.inputs / "tum/a_directory.tum")
        for name, path in (("is-a-directory", d), ("missing", B.inputs / "tum/missing.tum")):
            run = B.std_run(f"tum-{name}", "grid", bag, SCENE, "error", names=(str(path),),
                            extra=["--poses", str(path), "--base-frame", "base_link"], label="grid tum")
            B.add_runs(f"tum-{name}", "tum-file", path, [run])


# ---------------------------------------------------------------------------- output paths


def _read_only_dir_works() -> bool:
    """Whether permissions are enforced here (not as root, say)."""
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp) / "ro"
        d.mkdir()
        d.chmod(0o555)
        try:
            (d / "probe").write_bytes(b"")
        except PermissionError:
            return True
        finally:
            d.chmod(0o755)
        return False


def _output_cases(B: _Builder) -> None:
    bag = B.scene_bag("mcap")
    b = str(bag)
    full = B.full
    ro_skip = None if _read_only_dir_works() else "permissions are not enforced here (running as root?)"

    def out_argv(command: str, out: str) -> list[str]:
        return {
            "tf point": ["tf", "point", b, "--out", out, "--point", "1", "0", "0", "--frame", "map", "--force"],
            "map-cloud": ["map-cloud", b, "--out", out, "--sample", "1", "--force"],
            "ndt-odom": ["ndt-odom", b, "--out", out, "--force"],
            "grid": ["grid", b, "--out", out, "--force"],
            "tf echo": ["tf", "echo", b, "map", "base_link", "--csv", out, "--force"],
            "tf frames": ["tf", "frames", b, "--dot", out, "--force"],
            "simulate": ["simulate", out, "--duration", "1", "--no-cloud", "--force"],
        }[command]

    commands = B.pick(("grid", "tf echo", "simulate"), ("tf point", "map-cloud", "ndt-odom", "grid", "tf echo",
                                                           "tf frames", "simulate"))
    for command in commands:
        slug = command.replace(" ", "-")
        # under /proc (cannot be created by anyone)
        target = f"/proc/bagtools-robustness/{slug}"
        B.add_runs(f"output-under-proc-{slug}", "output-path", None,
                   [Run(command, out_argv(command, target), "error", names=("/proc",))])
        # under an existing regular file; the file must survive
        watch = B.out_dir(f"output-under-file-{slug}", "w")
        target = str(watch / "notes.txt" / "out")
        B.add_runs(f"output-under-file-{slug}", "output-path", None,
                   [Run(command, out_argv(command, target), "error", watch=watch, prefill=dict(USER_FILES),
                        names=(str(watch / "notes.txt"),))])
        # in a read-only directory
        watch = B.out_dir(f"output-read-only-{slug}", "ro")
        target = str(watch / "out")
        run = Run(command, out_argv(command, target), "error", watch=watch, prefill=dict(USER_FILES), names=(str(watch),))
        original = run.prepare

        def prepare_ro(original=original, watch=watch) -> None:
            original()
            watch.chmod(0o555)
        run.prepare = prepare_ro  # type: ignore[method-assign]
        B.add_runs(f"output-read-only-{slug}", "output-path", None, [run], skip=ro_skip)
        if full and command not in ("tf echo", "tf frames", "simulate"):
            # --out is an existing regular file
            watch = B.out_dir(f"output-is-a-file-{slug}", "w")
            target = str(watch / "notes.txt")
            B.add_runs(f"output-is-a-file-{slug}", "output-path", None,
                       [Run(command, out_argv(command, target), "error", watch=watch, prefill=dict(USER_FILES),
                            names=(target,))])


# ---------------------------------------------------------------------------- data loss


def _data_loss_cases(B: _Builder) -> None:
    bag = B.scene_bag("mcap")
    b = str(bag)
    full = B.full
    # A directory of user files given where a file output is expected, with --force: refuse, keep every file.
    for command, argv_of in (
            ("tf echo", lambda d: ["tf", "echo", b, "map", "base_link", "--csv", d, "--force"]),
            ("tf frames", lambda d: ["tf", "frames", b, "--dot", d, "--force"]),
    ):
        watch = B.out_dir(f"dataloss-{command.replace(' ', '-')}-into-user-dir", "mydir")
        B.add_runs(f"dataloss-{command.replace(' ', '-')}-into-user-dir", "data-loss", bag,
                   [Run(command, argv_of(str(watch)), "error", watch=watch, prefill=dict(USER_FILES),
                        names=(str(watch),))])
    # simulate over a non-bag directory of user files, with --force: refuse.
    watch = B.out_dir("dataloss-simulate-over-user-dir", "mydir")
    B.add_runs("dataloss-simulate-over-user-dir", "data-loss", None,
               [Run("simulate", ["simulate", str(watch), "--duration", "1", "--no-cloud", "--force"], "error",
                    watch=watch, prefill=dict(USER_FILES), names=(str(watch),))])
    # simulate over a file of the user's, with --force: refuse too (it is not a bag directory).
    if full:
        watch = B.out_dir("dataloss-simulate-over-user-file", "w")
        B.add_runs("dataloss-simulate-over-user-file", "data-loss", None,
                   [Run("simulate", ["simulate", str(watch / "notes.txt"), "--duration", "1", "--no-cloud", "--force"],
                        "error", watch=watch, prefill=dict(USER_FILES), names=(str(watch / "notes.txt"),))])
        # simulate over its own earlier bag (it carries bagtools' mark) with --force: allowed (replaces the bag only).
        watch = B.out_dir("dataloss-simulate-over-own-bag", "w")
        src = B.scene_bag("mcap")
        bag_files = {"sim/metadata.yaml": (src / "metadata.yaml").read_bytes(),
                     "sim/sim_0.mcap": (src / "scene_mcap.mcap").read_bytes()}
        mark = json.dumps({"written_by": "bagtools simulate", "files": ["metadata.yaml", "sim_0.mcap"]}).encode()
        prefill = {**USER_FILES, "sim": None, **bag_files, "sim/.bagtools-output.json": mark}
        B.add_runs("dataloss-simulate-over-own-bag", "data-loss", None,
                   [Run("simulate", ["simulate", str(watch / "sim"), "--duration", "1", "--no-cloud", "--force"], "ok",
                        watch=watch, prefill=prefill, own=("sim",), names=(str(watch / "sim"),))])
        # ... but a recording of the same shape without the mark (ros2 bag record's) is never replaced.
        watch = B.out_dir("dataloss-simulate-over-recording", "w")
        B.add_runs("dataloss-simulate-over-recording", "data-loss", None,
                   [Run("simulate", ["simulate", str(watch / "sim"), "--duration", "1", "--no-cloud", "--force"],
                        "error", watch=watch, prefill={**USER_FILES, "sim": None, **bag_files},
                        names=(str(watch / "sim"),))])
    # A failed run into a fresh --out must not leave the directory behind.
    missing = B.inputs / "dataloss/missing_bag"
    for command in B.pick(("grid",), ("tf point", "map-cloud", "ndt-odom", "grid")):
        watch = B.out_dir(f"dataloss-fresh-out-{command}", "new_out")
        run = B.std_run(f"dataloss-fresh-out-{command}", command, missing, SCENE, "error")
        run.watch, run.prefill = watch, None
        run.argv[run.argv.index("--out") + 1] = str(watch)
        B.add_runs(f"dataloss-fresh-out-{command}", "data-loss", missing, [run],
                   note="a failed run must not create --out either")
    # Runs that fail after the work (every scan unusable) with a prefilled --out and --force.
    nan_scans = edit(B.scene, "/scan", lambda s: setattr(s, "ranges", np.full_like(s.ranges, np.nan)), "all")
    path = B.write_scene("dataloss/all_scans_nan", nan_scans)
    B.add("dataloss-late-failure-all-scans-nan", "data-loss", path, ("ndt-odom", "grid", "map-cloud scan"),
          "warn_or_error", SCENE, note="a run that refuses late must still leave --out untouched")


# ---------------------------------------------------------------------------- valid inputs


def _baseline_cases(B: _Builder) -> None:
    """Valid bags: every command must succeed (and with --force replace only its own outputs)."""
    full = B.full
    B.add("valid-scene-mcap", "valid", B.scene_bag("mcap"),
          B.pick(("info", "tf echo", "tf point", "map-cloud", "ndt-odom", "grid"), (*ALL_COMMANDS, "grid gt")), "ok")
    B.add("valid-scene-sqlite3", "valid", B.scene_bag("sqlite3"), B.pick(("tf echo",), (*ALL_COMMANDS, "grid gt")), "ok")
    B.add("valid-scene-ros1", "valid", B.scene_bag("ros1"), B.pick(("tf echo",), (*ALL_COMMANDS, "grid gt")), "ok")
    if full:
        B.add("valid-scene-plain-mcap", "valid", B.scene_bag("plain"), ALL_COMMANDS, "ok")
        B.add("valid-scene-bare-mcap", "valid", B.scene_bag("mcap") / "scene_mcap.mcap", ALL_COMMANDS, "ok")
        B.add("valid-fixture-random", "valid", RANDOM, (*ALL_COMMANDS, "grid gt"), "ok", RANDOM_PROFILE)
        B.add("valid-fixture-lap", "valid", LAP, ALL_COMMANDS, "ok", LAP_PROFILE)
    real = [("tf_example-dir", REAL_DIR / "tf_example", TF_EXAMPLE, True),
            ("tf_example-bag", REAL_DIR / "tf_example.bag", TF_EXAMPLE, True),
            ("nav2-mcap", REAL_DIR / "nav2_turtlebot.mcap", NAV2, False),
            ("turtlebot3-bag", REAL_DIR / "turtlebot3_real_lidar_odom.bag", TURTLEBOT3, False),
            ("csail_odom", REAL_DIR / "csail_odom", CSAIL, False)]
    for name, path, prof, small in real:
        if not path.exists() or not (full or small):
            continue
        B.add(f"valid-real-{name}", "valid", path, B.pick(("tf echo",), ALL_COMMANDS), "ok", prof)


# ---------------------------------------------------------------------------- entry point


def build_corpus(dest: Path, size: str = "small") -> list[Case]:
    """Write the corpus inputs under ``dest`` and return its cases ('small': the test suite's, 'full': all)."""
    B = _Builder(Path(dest), size)
    _baseline_cases(B)
    _basic_cases(B)
    _mcap_cases(B)
    _metadata_cases(B)
    _sqlite_cases(B)
    _ros1_cases(B)
    _content_cases(B)
    _option_cases(B)
    _output_cases(B)
    _data_loss_cases(B)
    for case in B.cases:
        for run in case.runs:
            if run.expect not in EXPECTATIONS:
                raise ValueError(f"{case.name}: unknown expectation {run.expect!r}")
    return B.cases


def summary(cases: list[Case]) -> str:
    runs = sum(len(c.runs) for c in cases)
    groups: dict[str, int] = {}
    for c in cases:
        groups[c.group] = groups.get(c.group, 0) + 1
    return f"{len(cases)} inputs, {runs} runs ({', '.join(f'{g} {n}' for g, n in groups.items())})"


if __name__ == "__main__":
    import sys
    import tempfile

    size = sys.argv[1] if len(sys.argv) > 1 else "small"
    with tempfile.TemporaryDirectory() as tmp:
        print(summary(build_corpus(Path(tmp), size)))
