"""The committed fixture bags are reproducible: regenerating them gives the same messages."""

from __future__ import annotations

from pathlib import Path

from rosbags.highlevel import AnyReader

from fixtures.generate import FIXTURES, FIXTURES_DIR, generate


def messages(path: Path) -> dict[str, list[tuple[int, bytes]]]:
    """topic -> [(log time ns, serialized bytes)] in bag order."""
    out: dict[str, list[tuple[int, bytes]]] = {}
    with AnyReader([path]) as reader:
        for conn, log_ns, raw in reader.messages():
            out.setdefault(conn.topic, []).append((log_ns, bytes(raw)))
    return out


def test_regenerated_fixtures_have_identical_messages(tmp_path: Path) -> None:
    fresh = generate(tmp_path)
    assert [p.name for p in fresh] == list(FIXTURES)
    for path in fresh:
        committed = FIXTURES_DIR / path.name
        assert (committed / "metadata.yaml").exists(), f"missing fixture {committed}: run python -m fixtures.generate"
        assert messages(path) == messages(committed)
        assert sum(f.stat().st_size for f in committed.iterdir()) < 1_000_000
