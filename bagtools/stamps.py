"""Stamps written as text (a CARMEN log's, a TUM file's) read exactly: decimal seconds to int nanoseconds, never
through a float."""

from __future__ import annotations


def seconds_text_to_ns(text: str) -> int:
    """Decimal seconds ("1234.567890", "-3.5", or C's %g form "1.10002e+09", as a logger that wrote six
    significant digits did) as int nanoseconds, exactly; digits beyond the nanosecond are cut. ValueError for
    anything else (no "nan", "inf", "0x10", "1_0", "+1", or an exponent of more than two digits)."""
    text = text.strip()
    mantissa, e, exponent = text.replace("E", "e").partition("e")
    whole, _, frac = mantissa.partition(".")
    if not whole.lstrip("-").isdigit() or (frac and not frac.isdigit()) or \
            (e and not (exponent.lstrip("+-").isdigit() and len(exponent.lstrip("+-")) <= 2)):
        raise ValueError(f"not a timestamp: {text!r}")
    digits = whole.lstrip("-") + frac
    point = len(whole.lstrip("-")) + 9 + (int(exponent) if e else 0)  # where the point falls, in nanoseconds
    ns = int((digits + "0" * max(point - len(digits), 0))[:max(point, 0)] or 0)
    return -ns if whole.startswith("-") else ns


__all__ = ["seconds_text_to_ns"]
