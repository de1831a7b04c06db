"""Numbers in the reproduction's tables: one fixed notation per column or claim, never
scientific notation (31130, 0.000152)."""

from __future__ import annotations

import math
import numbers
from collections.abc import Iterable
from typing import Any

from cosim.run.console import decimal_exponent

SIGNIFICANT = 3  # significant digits a fixed notation gives the smallest non-zero magnitude
MAX_DECIMALS = 9  # the most decimals a fixed notation shows (below: zero)


def _finite(values: Iterable[Any]) -> list[float]:
    """The finite numbers (not booleans) among ``values``."""
    return [float(v) for v in values if isinstance(v, numbers.Real) and not isinstance(v, bool)
            and math.isfinite(v)]


def decimals_for(values: Iterable[Any], significant: int = SIGNIFICANT) -> int:
    """The decimals of one fixed notation for ``values`` (a table's column, or one claim's
    median, CI and worst member): none when every finite value is a whole number, else enough
    for ``significant`` digits of the smallest non-zero magnitude, at most
    :data:`MAX_DECIMALS`. Non-numbers are left out."""
    finite = _finite(values)
    nonzero = [abs(v) for v in finite if v != 0.0]
    if not nonzero or all(v.is_integer() for v in finite):
        return 0
    return min(MAX_DECIMALS,
               max(0, significant - 1 - decimal_exponent(min(nonzero), significant)))


def fixed(value: float, decimals: int) -> str:
    """``value`` in fixed notation with ``decimals`` decimals (31130, 0.000152; never
    3.113e+04): ``-`` for NaN, a zero without its sign."""
    if math.isnan(value):
        return "-"
    if math.isinf(value):
        return "inf" if value > 0 else "-inf"
    text = f"{value:.{decimals}f}"
    return text.lstrip("-") if float(text) == 0.0 else text


def number(value: float) -> str:
    """One number alone in fixed notation (:func:`fixed` at :func:`decimals_for` of it)."""
    return fixed(value, decimals_for([value]))
