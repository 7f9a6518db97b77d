"""Time steps over a bag: a fixed rate between two stamps, int nanoseconds."""

from __future__ import annotations

import numpy as np

from bagtools.tf.exceptions import InvalidArgumentException


def sample_stamps(first_ns: int, last_ns: int, rate_hz: float) -> np.ndarray:
    """Stamps first_ns, first_ns + 1/rate, ... up to last_ns inclusive, (N,) int64 ns.

    Raises InvalidArgumentException for a rate that is not positive and finite.
    """
    if not np.isfinite(rate_hz) or rate_hz <= 0:
        raise InvalidArgumentException(f"rate must be a positive number of Hz, got {rate_hz}")
    if last_ns < first_ns:
        return np.empty(0, dtype=np.int64)
    step = 1e9 / rate_hz
    count = int(np.floor((last_ns - first_ns) / step)) + 1
    return first_ns + np.round(np.arange(count) * step).astype(np.int64)
