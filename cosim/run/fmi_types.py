"""FMI 2.0 and 3.0 variable types in one place (FMI 2.0.4 sec. 2.2.7 and 2.1.7; FMI 3.0
sec. 2.4.7 and 2.2.6.2).

Which get/set function each type goes through (an FMI 2 Enumeration uses the Integer functions,
an FMI 3 one the Int64 functions, its values are the item values), and how a scenario value is
checked and converted: a Real / Float64 / Float32 is a finite number inside [min, max], an
Integer / Int8..UInt64 an int inside [min, max] and the type's range, a Boolean a bool, a
String a str, a Binary a string of hexadecimal digits (``"00ff"``), an Enumeration an item
value or an item name (``mode = "fast"``).
"""

from __future__ import annotations

import math
from typing import Any

from cosim.fmu.declare import out_of_range

FLOATS = ("Real", "Float64", "Float32")
# FMI 3 integer types and their ranges (FMI 2 Integer: 32 bits)
INTEGERS = {"Integer": (-2**31, 2**31 - 1),
            **{f"Int{n}": (-2**(n - 1), 2**(n - 1) - 1) for n in (8, 16, 32, 64)},
            **{f"UInt{n}": (0, 2**n - 1) for n in (8, 16, 32, 64)}}
TYPES = ("Real", "Integer", "Boolean", "String", "Enumeration",
         "Float64", "Float32", *[k for k in INTEGERS if k != "Integer"], "Binary")
NUMERIC = tuple(t for t in TYPES if t not in ("String", "Binary"))  # recordable as numbers

# FMI 2 type -> the fmi2Get/Set function family it goes through (FMI 3: the type's own name,
# Enumeration Int64: cosim.run.master.fmi3.family_of)
FUNCTIONS = {"Real": "Real", "Integer": "Integer", "Enumeration": "Integer",
             "Boolean": "Boolean", "String": "String"}
# an FMI 2 type and the FMI 3 type of the same C values (connections across versions)
FMI3_TWIN = {"Real": "Float64", "Integer": "Int32"}


def same_type(a: str, b: str) -> bool:
    """Can an output of type ``a`` feed an input of type ``b`` unchanged?"""
    return FMI3_TWIN.get(a, a) == FMI3_TWIN.get(b, b)


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
    if kind in FLOATS:
        return float(value)
    if kind in INTEGERS or kind == "Enumeration":
        if kind == "Enumeration" and isinstance(value, str):
            return (items or {})[value]
        return int(value)
    if kind == "Boolean":
        return bool(value)
    if kind == "Binary":
        return bytes.fromhex(value) if isinstance(value, str) else bytes(value)
    return str(value)


def check_value(variable: Any, value: Any, ranges: bool = True) -> str | None:
    """None when ``value`` is a valid scenario value for ``variable`` (within its [min, max]
    unless ``ranges`` is False), else why not."""
    kind = variable.type
    if kind in FLOATS:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            return f"is {kind}, got {value!r}"
        if not math.isfinite(float(value)):
            return f"{value!r} is not finite"
    elif kind in INTEGERS:
        if isinstance(value, bool) or not isinstance(value, int):
            return f"is {kind}, got {value!r}"
        lo, hi = INTEGERS[kind]
        if not lo <= value <= hi:
            return f"= {value} is outside the range of {kind} [{lo}, {hi}]"
    elif kind == "Binary":
        try:
            bytes.fromhex(value)
        except (TypeError, ValueError):
            return f"is Binary, got {value!r}; expected hexadecimal digits such as \"00ff\""
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
        return f"has type {kind!r}, which the master cannot set"
    if ranges and (kind in FLOATS or kind in INTEGERS or kind == "Enumeration"):
        lo = float(variable.min) if variable.min is not None else -math.inf
        hi = float(variable.max) if variable.max is not None else math.inf
        if not lo <= float(value) <= hi:
            unit = getattr(variable, "unit", None)
            return (f"= {out_of_range(value, variable.min, variable.max)}"
                    + (f" ({unit or 'no unit'})" if kind in FLOATS else ""))
    return None
