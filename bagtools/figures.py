"""Small helpers shared by the commands that draw PNGs (matplotlib, Agg)."""

from __future__ import annotations

import warnings
from typing import Any


def tidy_layout(fig: Any) -> None:
    """``fig.tight_layout()``, silently left as it is when the decorations cannot fit (long labels, many legend
    entries): a cramped picture is no reason for a warning on the user's terminal."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="Tight layout not applied", category=UserWarning)
        fig.tight_layout()
