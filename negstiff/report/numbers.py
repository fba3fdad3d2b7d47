"""How a number reads in a report: its significant figures, in scientific notation when very large or small."""

from __future__ import annotations

import math
from typing import Any


def fmt(x: Any, digits: int = 4) -> str:
    """A number as a person reads it (``digits`` significant figures), or the value as text; None (nothing to
    show, a table's empty cell) as "-".
    """
    if x is None:
        return "-"
    if isinstance(x, bool):
        return str(x)
    if isinstance(x, int):  # a count is exact: every digit (a record's 40000 samples had read "4e+04")
        return str(x)
    if isinstance(x, (int, float)):
        if not math.isfinite(x):
            return str(x)
        if x != 0 and (abs(x) >= 1e5 or abs(x) < 1e-3):
            return f"{x:.{digits - 1}e}"
        return f"{x:.{digits}g}"
    return str(x)


def fmt_interval(lo: float, hi: float, digits: int = 4) -> tuple[str, str]:
    """The two ends of an interval, each with ``digits`` significant figures or as many more as it takes
    for them to read apart (up to 15): ``7.770e+05`` and ``7.770e+05`` become ``7.7698e+05`` and
    ``7.7704e+05``. Equal ends print equal.
    """
    for d in range(digits, 16):
        a, b = fmt(lo, d), fmt(hi, d)
        if a != b or lo == hi:
            return a, b
    return fmt(lo, 15), fmt(hi, 15)
