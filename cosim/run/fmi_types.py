"""FMI 2.0 variable types in one place (FMI 2.0.4 sec. 2.2.7 and 2.1.7).

Which get/set function each type goes through (an Enumeration uses the Integer functions, its
values are the item values), and how a scenario value is checked and converted: a Real is a
finite number inside [min, max], an Integer an int inside [min, max], a Boolean a bool, a String
a str, an Enumeration an item value or an item name (``mode = "fast"``).
"""

from __future__ import annotations

import math
from typing import Any

from cosim.fmu.declare import out_of_range

TYPES = ("Real", "Integer", "Boolean", "String", "Enumeration")
NUMERIC = ("Real", "Integer", "Boolean", "Enumeration")  # recordable as numbers

# FMI type -> the fmi2Get/Set function family it goes through
FUNCTIONS = {"Real": "Real", "Integer": "Integer", "Enumeration": "Integer",
             "Boolean": "Boolean", "String": "String"}


def enumeration_items(variable: Any) -> dict[str, int]:
    """Item name -> value of an Enumeration variable (fmpy ``ModelVariable``)."""
    declared = getattr(variable, "declaredType", None)
    return {item.name: int(item.value) for item in getattr(declared, "items", None) or []}


def get_values(slave: Any, kind: str, vrs: list[int]) -> list[Any]:
    """fmi2Get<type> of ``vrs``, all of FMI type ``kind``."""
    return list(getattr(slave, f"get{FUNCTIONS[kind]}")(vrs))


def set_values(slave: Any, kind: str, vrs: list[int], values: list[Any]) -> None:
    """fmi2Set<type> of ``vrs`` (values already converted by :func:`to_fmi`)."""
    getattr(slave, f"set{FUNCTIONS[kind]}")(vrs, values)


def to_fmi(kind: str, value: Any, items: dict[str, int] | None = None) -> Any:
    """A Python value as the setter of ``kind`` takes it (an Enumeration name -> its value)."""
    if kind == "Real":
        return float(value)
    if kind in ("Integer", "Enumeration"):
        if kind == "Enumeration" and isinstance(value, str):
            return (items or {})[value]
        return int(value)
    if kind == "Boolean":
        return bool(value)
    return str(value)


def check_value(variable: Any, value: Any, ranges: bool = True) -> str | None:
    """None when ``value`` is a valid scenario value for ``variable`` (within its [min, max]
    unless ``ranges`` is False), else why not."""
    kind = variable.type
    if kind == "Real":
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            return f"is Real, got {value!r}"
        if not math.isfinite(float(value)):
            return f"{value!r} is not finite"
    elif kind == "Integer":
        if isinstance(value, bool) or not isinstance(value, int):
            return f"is Integer, got {value!r}"
    elif kind == "Boolean":
        if not isinstance(value, bool):
            return f"is Boolean, got {value!r}"
    elif kind == "String":
        if not isinstance(value, str):
            return f"is String, got {value!r}"
    elif kind == "Enumeration":
        items = enumeration_items(variable)
        choices = ", ".join(f"{n} ({v})" for n, v in items.items())
        if isinstance(value, str):
            if value not in items:
                return f"is an Enumeration, {value!r} is not one of its items: {choices}"
            value = items[value]
        elif isinstance(value, bool) or not isinstance(value, int):
            return f"is an Enumeration, got {value!r}; expected an item name or value: {choices}"
        elif items and value not in items.values():
            return f"is an Enumeration, {value} is not an item value: {choices}"
    else:
        return f"has type {kind!r}, which FMI 2.0 does not define"
    if ranges and kind in ("Real", "Integer", "Enumeration"):
        lo = float(variable.min) if variable.min is not None else -math.inf
        hi = float(variable.max) if variable.max is not None else math.inf
        if not lo <= float(value) <= hi:
            unit = getattr(variable, "unit", None)
            return (f"= {out_of_range(value, variable.min, variable.max)}"
                    + (f" ({unit or 'no unit'})" if kind == "Real" else ""))
    return None
