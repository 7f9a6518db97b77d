"""Time steps over a bag: a fixed rate between two stamps, int nanoseconds."""

from __future__ import annotations

import numpy as np

from bagtools.limits import check_memory
from bagtools.tf.exceptions import InvalidArgumentException


#: Memory a time step costs its consumers (a 4x4 transform per target and point, columns, text).
BYTES_PER_STEP = 1024


def sample_stamps(first_ns: int, last_ns: int, rate_hz: float, bytes_per_step: int = BYTES_PER_STEP) -> np.ndarray:
    """Stamps first_ns, first_ns + 1/rate, ... up to last_ns inclusive, (N,) int64 ns.

    Raises InvalidArgumentException for a rate that is not positive and finite,
    and :class:`~bagtools.limits.MemoryBudgetError` when the steps (at
    ``bytes_per_step`` each) would not fit in memory (a high rate over a long
    span, or a stray stamp far from the rest).
    """
    if not np.isfinite(rate_hz) or rate_hz <= 0:
        raise InvalidArgumentException(f"rate must be a positive number of Hz, got {rate_hz}")
    if last_ns < first_ns:
        return np.empty(0, dtype=np.int64)
    step = 1e9 / rate_hz
    if not np.isfinite(step):  # a rate so low that one step is longer than any span: the first stamp only
        return np.array([first_ns], dtype=np.int64)
    count_f = np.floor((last_ns - first_ns) / step) + 1
    check_memory(count_f * bytes_per_step, f"{count_f:.3g} time steps at {rate_hz:g} Hz over {(last_ns - first_ns) / 1e9:.6g} s",
                 "lower --rate")
    count = int(count_f)
    return first_ns + np.round(np.arange(count) * step).astype(np.int64)
