"""The memory budget: an option or a damaged input must never make bagtools allocate more than the machine has.

Every allocation whose size an option or the data decides (time steps of
``tf echo``, NDT grids, occupancy grids, voxel indexes) is checked against
:func:`memory_budget_bytes` before it is made, and refused with a message that
says what was asked, what the limit is, and how to change it.
"""

from __future__ import annotations

import math
import os

from bagtools.errors import BagtoolsError

ENV_VAR = "BAGTOOLS_MEMORY_BUDGET"
#: A map's origin or a pose in it beyond this (m) from its frame's origin is damage or a typo, not a building.
MAX_MAP_ORIGIN_M = 1.0e7
_UNITS = {"": 1, "k": 1 << 10, "m": 1 << 20, "g": 1 << 30, "t": 1 << 40}


class MemoryBudgetError(BagtoolsError):
    """An allocation would exceed the memory budget."""


def format_bytes(n: float) -> str:
    """Bytes as a short human figure (e.g. '61.0 GB')."""
    for unit, size in (("TB", 1e12), ("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if n >= size:
            return f"{n / size:.1f} {unit}"
    return f"{n:.0f} B"


def memory_budget_bytes() -> int:
    """The budget: ``$BAGTOOLS_MEMORY_BUDGET`` (e.g. '8G') if set, else a quarter of physical memory (at least 1 GiB)."""
    text = os.environ.get(ENV_VAR, "").strip().lower().removesuffix("b")
    if text:
        number, unit = (text[:-1], text[-1]) if text[-1] in _UNITS else (text, "")
        try:
            return int(float(number) * _UNITS[unit])
        except ValueError:
            raise BagtoolsError(f"{ENV_VAR}={os.environ[ENV_VAR]!r} is not a size such as 8G or 500M") from None
    try:
        physical = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        physical = 8 << 30
    return max(1 << 30, physical // 4)


def check_memory(n_bytes: float, what: str, hint: str = "") -> None:
    """Raise :class:`MemoryBudgetError` if ``what`` would need more than the budget (or an unbounded amount)."""
    budget = memory_budget_bytes()
    if math.isfinite(n_bytes) and n_bytes <= budget:
        return
    need = format_bytes(n_bytes) if math.isfinite(n_bytes) else "an unbounded amount"
    tail = f"; {hint}" if hint else ""
    raise MemoryBudgetError(f"{what} would need {need} of memory, over the budget of {format_bytes(budget)} "
                            f"(set {ENV_VAR} to change it){tail}")
