"""What a column of a run's table is: its description and declared unit, read from its FMU's
modelDescription, the unit it is drawn in, and whether it is held between the FMU's events.
Shared by the writer (:mod:`cosim.run.results`: ``results.units.json``) and every figure
(:mod:`cosim.run.figures`)."""

from __future__ import annotations

import functools
from pathlib import Path
from typing import Any

TIME_INFO = ("simulation time", "s")  # (description, unit) of the column ``time``


_UNIT_DISPLAY = {"N": (1e-3, "kN"), "m/s2": (1.0, "m/s²"), "%": (1.0, "%"),
                 "Pa": (1e-3, "kPa"), "W": (1e-3, "kW"), "m/s": (3.6, "km/h")}


def display_unit(unit: str | None) -> tuple[float, str | None]:
    """(scale, label) to plot a quantity declared in ``unit``: kN for N, m/s² for m/s2, ..."""
    if unit is None:
        return 1.0, None
    return _UNIT_DISPLAY.get(unit, (1.0, unit))


@functools.lru_cache(maxsize=64)
def _model_variables(path: str, mtime_ns: int) -> dict[str, Any]:
    """Name -> fmpy ModelVariable of the FMU at ``path`` (as of ``mtime_ns``: a rebuilt FMU
    is read again)."""
    from fmpy import read_model_description

    md = read_model_description(path, validate=False)
    return {v.name: v for v in md.modelVariables}


def variable_info(scenario: Any, ref: str) -> tuple[str, str | None]:
    """(description, declared unit) of ``"instance.variable"`` from its FMU's
    modelDescription; the name itself and None where it has none."""
    try:
        comp, var = ref.split(".", 1)
        base = var.split("[", 1)[0]
        path = Path(scenario.components[comp].fmu_path)
        by_name = _model_variables(str(path), path.stat().st_mtime_ns)
        found = by_name.get(var) or by_name[base]  # the element itself, else its vector
        unit = found.unit or (found.declaredType.unit if found.declaredType is not None
                              else None)
        text = found.description or ref
        if found.name != var:  # one element of a vector variable: name it
            text += f" {var[len(base):]}"
        return text, unit
    except Exception:  # noqa: BLE001 - a plot label must never fail a run
        return ref, None


def column_info(scenario: Any, columns: Any) -> dict[str, tuple[str, str | None]]:
    """Per column of a run's table: (description, declared unit), :data:`TIME_INFO` for
    ``time``, :func:`variable_info` for the others."""
    return {str(c): TIME_INFO if c == "time" else variable_info(scenario, str(c))
            for c in columns}


def column_units(scenario: Any, columns: Any) -> dict[str, str | None]:
    """Per column of a run's table: the unit its FMU declares (None where none), as
    ``results.units.json`` holds them."""
    return {column: unit for column, (_, unit) in column_info(scenario, columns).items()}


def variable_unit(scenario: Any, ref: str) -> str | None:
    """The declared unit of ``"instance.variable"`` from its FMU's modelDescription."""
    return variable_info(scenario, ref)[1]


def axis_label(text: str, unit: str | None) -> str:
    """``text (unit)`` in the display unit, ``text`` for a dimensionless quantity."""
    label = display_unit(unit)[1]
    return f"{text} ({label})" if label and label != "1" else text


def is_held(scenario: Any, ref: str) -> bool:
    """True for an output of a sampled or self-triggered FMU (a ``sample_time`` in the
    scenario, or a ``sample_time`` parameter or ``next_event_time`` output declared): it is
    held between the FMU's events, so it is drawn as steps."""
    try:
        from fmpy import read_model_description

        component = scenario.components[ref.split(".", 1)[0]]
        if component.sample_time:
            return True
        md = read_model_description(str(component.fmu_path), validate=False)
        return any(v.name in ("sample_time", "next_event_time") for v in md.modelVariables)
    except Exception:  # noqa: BLE001 - a plot must never fail a run
        return False
