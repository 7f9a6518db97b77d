"""The committed fixture bags are reproducible: regenerating them gives the same messages.

Bytes may differ in the last bits of a float from one numpy or libm release to the
next (sin, cos, sqrt of a few ULP), so messages are compared field by field:
stamps, strings, integers and array shapes exactly, floats to 1e-9 (relative).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
from rosbags.highlevel import AnyReader

from fixtures.generate import FIXTURES, FIXTURES_DIR, generate


def messages(path: Path) -> dict[str, list[tuple[int, Any]]]:
    """topic -> [(log time ns, deserialized message)] in bag order."""
    out: dict[str, list[tuple[int, Any]]] = {}
    with AnyReader([path]) as reader:
        for conn, log_ns, raw in reader.messages():
            out.setdefault(conn.topic, []).append((log_ns, reader.deserialize(raw, conn.msgtype)))
    return out


def assert_close(a: Any, b: Any, where: str) -> None:
    """Recursive equality of two rosbags messages; floats to 1e-9 relative."""
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        a, b = np.asarray(a), np.asarray(b)
        assert a.shape == b.shape and a.dtype == b.dtype, where
        if a.dtype.kind == "f":
            np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-12, err_msg=where)
        else:
            assert np.array_equal(a, b), where
    elif isinstance(a, float):
        assert math.isclose(a, b, rel_tol=1e-9, abs_tol=1e-12) or (math.isnan(a) and math.isnan(b)), f"{where}: {a} != {b}"
    elif isinstance(a, (list, tuple)):
        assert len(a) == len(b), where
        for i, (x, y) in enumerate(zip(a, b)):
            assert_close(x, y, f"{where}[{i}]")
    elif hasattr(a, "__dataclass_fields__"):
        assert type(a).__name__ == type(b).__name__, where
        for name in a.__dataclass_fields__:
            assert_close(getattr(a, name), getattr(b, name), f"{where}.{name}")
    else:
        assert a == b, f"{where}: {a!r} != {b!r}"


def test_regenerated_fixtures_have_the_same_messages(tmp_path: Path) -> None:
    fresh = generate(tmp_path)
    assert [p.name for p in fresh] == list(FIXTURES)
    for path in fresh:
        committed = FIXTURES_DIR / path.name
        assert (committed / "metadata.yaml").exists(), f"missing fixture {committed}: run python -m fixtures.generate"
        new, old = messages(path), messages(committed)
        assert sorted(new) == sorted(old)
        for topic in new:
            assert [t for t, _ in new[topic]] == [t for t, _ in old[topic]], topic
            for i, ((_, a), (_, b)) in enumerate(zip(new[topic], old[topic])):
                assert_close(a, b, f"{path.name}{topic}#{i}")
        assert sum(f.stat().st_size for f in committed.iterdir()) < 1_000_000
