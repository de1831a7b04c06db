"""Tables for an 80-column terminal (``cosim sweep``, ``cosim reproduce``): the full tables go
to files (csv, md); the console gets these.

:func:`fit_table` formats each column in one notation (:func:`column_cells`: integers as
such, other numbers with the same number of decimals, 4 significant digits on the column's
largest value, or all in scientific notation where that cannot show them; ``-`` for a missing
value), drops the prefix the key column's names share (stated above the table), and when the
columns do not fit ``width`` splits them into blocks, each repeating the key columns, so that
nothing is cut.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping, Sequence
from typing import Any

WIDTH = 80
GAP = "  "


def cell(value: Any, signed: bool = False) -> str:
    """A value as a short text: ``-`` for None/NaN, an integer as such, a float to 4
    significant digits (``signed``: with its sign), anything else as ``str``."""
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "-"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float) and value.is_integer() and abs(value) < 1e9 and not signed:
        return str(int(value))
    if isinstance(value, (int, float)):
        return f"{value:+.4g}" if signed else f"{value:.4g}"
    return str(value)


def decimal_exponent(value: float, significant: int) -> int:
    """The power of ten of ``value``'s leading digit as Python prints it to ``significant``
    (>= 1) significant digits (``f"{value:.{significant - 1}e}"``): 0.001 -> -3 exactly,
    whatever the platform's log10; a value that rounds up to the next power takes that power's
    (9.996e-4 at 3 digits prints 1.00e-03: -3), consistent with the digits shown. ``value``
    finite and non-zero."""
    return int(f"{value:.{significant - 1}e}".split("e")[1])


def _numeric(value: Any) -> bool:
    """A finite int or float (not a bool)."""
    return (isinstance(value, (int, float)) and not isinstance(value, bool)
            and math.isfinite(value))


def column_cells(values: Sequence[Any], signed: bool = False, digits: int = 4) -> list[str]:
    """The cells of one column in one notation. Its numbers: integers (every one integral,
    below 1e9 in magnitude) as integers; otherwise fixed-point with the same decimals for all,
    ``digits`` significant digits on the largest magnitude (less the trailing zeros every
    number has), where that lies in [1e-3, 1e6);
    otherwise all in scientific notation (``digits`` significant digits). ``signed``: numbers
    with their sign. Anything else as :func:`cell` gives it."""
    numbers = [float(v) for v in values if _numeric(v)]
    sign = "+" if signed else ""
    if not numbers:
        spec = ""
    elif all(n.is_integer() and abs(n) < 1e9 for n in numbers):
        spec = "int"
    else:
        largest = max(abs(n) for n in numbers)
        exponent = decimal_exponent(largest, digits) if largest > 0 else 0
        if -3 <= exponent < 6:
            decimals = max(0, digits - 1 - exponent)
            while decimals and all(f"{n:.{decimals}f}".endswith("0") for n in numbers):
                decimals -= 1  # 0.50 / 0.55, not 0.5000 / 0.5500
            spec = f"{sign}.{decimals}f"
        else:
            spec = f"{sign}.{digits - 1}e"
    cells = []
    for v in values:
        if not spec or not _numeric(v):
            cells.append(cell(v, signed))
        elif spec == "int":
            cells.append(f"{int(v):{sign}d}")
        else:
            cells.append(f"{float(v):{spec}}")
    return cells


def _is_number(text: str) -> bool:
    if text == "-":
        return True
    try:
        float(text)
    except ValueError:
        return False
    return True


def _shared_prefix(names: Sequence[str]) -> str:
    """The words (up to an ``_``) every name starts with, when there are several names."""
    if len(set(names)) < 2:
        return ""
    prefix = os.path.commonprefix(list(names))
    return prefix[: prefix.rfind("_") + 1]


def fit_table(rows: Sequence[Mapping[str, Any]], columns: Sequence[str],
              labels: Mapping[str, str] | None = None, keys: int = 1,
              signed: Sequence[str] = (), width: int = WIDTH, title: str = "") -> str:
    """``rows`` as a plain-text table of ``columns`` (headers from ``labels``, each column in
    one notation: :func:`column_cells`), the first ``keys`` columns on the left of every block;
    no line longer than ``width``."""
    labels = labels or {}
    by_column = [column_cells([r.get(c) for r in rows], c in signed) for c in columns]
    text = [[by_column[i][n] for i in range(len(columns))] for n in range(len(rows))]
    lines = [title] if title else []
    if text and keys:
        prefix = _shared_prefix([t[0] for t in text])
        if prefix:
            for t in text:
                t[0] = t[0][len(prefix):]
            lines.append(f"({columns[0]}: {prefix}...)")
    heads = [labels.get(c, c) for c in columns]
    widths = [max([len(heads[i]), *(len(t[i]) for t in text)]) for i in range(len(columns))]
    key_cols = list(range(min(keys, len(columns))))
    key_width = sum(widths[i] + len(GAP) for i in key_cols)
    for i in key_cols:  # a key wider than the line: cut it, the full name is in the file
        limit = max(8, width // 2 - len(GAP))
        if widths[i] > limit:
            widths[i] = limit
            for t in text:
                t[i] = t[i] if len(t[i]) <= limit else t[i][: limit - 1] + "~"
    key_width = sum(widths[i] + len(GAP) for i in key_cols)
    blocks: list[list[int]] = []
    current: list[int] = []
    used = key_width
    for i in range(len(key_cols), len(columns)):
        w = min(widths[i], width - key_width)
        widths[i] = w
        if current and used + w > width:
            blocks.append(current)
            current, used = [], key_width
        current.append(i)
        used += w + len(GAP)
    if current or not blocks:
        blocks.append(current)

    numeric = [all(_is_number(t[i]) for t in text) for i in range(len(columns))]

    def fmt(values: Sequence[str], cols: Sequence[int]) -> str:
        parts = []
        for i in cols:
            value = values[i] if len(values[i]) <= widths[i] else values[i][: widths[i] - 1] + "~"
            right = numeric[i]
            parts.append(value.rjust(widths[i]) if right else value.ljust(widths[i]))
        return GAP.join(parts).rstrip()

    for n, block in enumerate(blocks):
        cols = [*key_cols, *block]
        if n:
            lines.append("")
        lines.append(fmt(heads, cols))
        lines.append("-" * min(width, len(fmt(heads, cols))))
        lines += [fmt(t, cols) for t in text]
    return "\n".join(lines)
