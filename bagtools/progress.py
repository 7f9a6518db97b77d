"""The one progress bar helper. Writes to stderr and hides itself when not a TTY."""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from typing import TypeVar

from tqdm import tqdm

T = TypeVar("T")


def progress(items: Iterable[T], total: int | None = None, desc: str = "", unit: str = "msg") -> Iterator[T]:
    """Iterate ``items`` while showing a progress bar on an interactive stderr."""
    yield from tqdm(items, total=total, desc=desc, unit=unit, disable=None, leave=False, dynamic_ncols=True)


def progress_bar(total: float, desc: str = "", unit: str = "it") -> tqdm:
    """A manually updated progress bar (``bar.update(n)``; use as a context manager)."""
    return tqdm(total=total, desc=desc, unit=unit, disable=None, leave=False, dynamic_ncols=True)
