"""Batch CDR serialization of messages whose byte layout does not depend on their values.

A message type with fixed strings (frame ids, joint names) and fixed-length arrays serializes
to the same bytes everywhere but at the offsets of its numbers. ``FixedLayout.probe`` finds
those offsets once, by serializing one message (with the typestore) whose numbers are distinct
sentinels and locating each sentinel's bytes; ``pack`` then writes N messages at once with
numpy. The result is byte-identical to serializing each message (tests check it), at a small
fraction of the cost, which keeps the 200 Hz IMU and the 30 Hz streams cheap.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np

# Field kinds: CDR little-endian scalars.
_DTYPES = {"f8": np.dtype("<f8"), "i4": np.dtype("<i4"), "u4": np.dtype("<u4")}


@dataclass(frozen=True)
class FixedLayout:
    """The bytes of one message with every numeric field at ``offsets[name]`` (byte offset, dtype)."""

    template: bytes
    offsets: dict[str, tuple[int, np.dtype]]

    @classmethod
    def probe(cls, serialize: Callable[[Mapping[str, float]], bytes], fields: Mapping[str, str]) -> FixedLayout:
        """Locate ``fields`` (name -> "f8" | "i4" | "u4") in ``serialize(values)``.

        ``serialize`` builds and serializes one message from a value per field name. Raises
        ValueError if a field cannot be found exactly once or the layout depends on the values.
        """
        sentinels: dict[str, float] = {}
        for i, (name, kind) in enumerate(fields.items()):
            if kind == "f8":
                sentinels[name] = 1.0e200 * (1.0 + 0.001 * (i + 1)) + 0.123456789
            else:
                sentinels[name] = 0x3A5C_0000 + 0x101 * (i + 1)
        probe = serialize(sentinels)
        offsets: dict[str, tuple[int, np.dtype]] = {}
        for name, kind in fields.items():
            dtype = _DTYPES[kind]
            needle = np.array([sentinels[name]], dtype=dtype).tobytes()
            at = probe.find(needle)
            if at < 0 or probe.find(needle, at + 1) >= 0:
                raise ValueError(f"field {name!r} not found exactly once in the probe serialization")
            offsets[name] = (at, dtype)
        zeros = serialize({name: 0.0 if kind == "f8" else 0 for name, kind in fields.items()})
        if len(zeros) != len(probe):
            raise ValueError("message size depends on its values: not a fixed layout")
        return cls(zeros, offsets)

    @property
    def size(self) -> int:
        """Bytes per message."""
        return len(self.template)

    def pack(self, n: int, values: Mapping[str, np.ndarray | float]) -> np.ndarray:
        """N serialized messages as an (N, size) uint8 array; ``values`` per field: (N,) array or a scalar.

        Fields not in ``values`` keep the template's 0.
        """
        out = np.empty((n, self.size), dtype=np.uint8)
        out[:] = np.frombuffer(self.template, dtype=np.uint8)
        for name, column in values.items():
            at, dtype = self.offsets[name]
            col = np.broadcast_to(np.asarray(column).astype(dtype, copy=False), (n,))
            out[:, at:at + dtype.itemsize] = np.ascontiguousarray(col).view(np.uint8).reshape(n, dtype.itemsize)
        return out
