"""Which cases of a per-model matrix the default suite runs, and which only the slow one.

A whole-FMU check repeated over every model (the compliance suite, fmpy's default experiment,
the C hosts, fmpy's build from the FMU's sources, libcosim and SSP against our master) finds a
fault of one model's declarations or sources. The default suite (``python -m pytest``, the
README's test command) runs it on one model of each family of code, :data:`REPRESENTATIVES`;
the others are marked slow and run in ``pytest -m slow`` (CI's second step), so every model is
still checked before a change lands. Of the scenarios, the sample is the first whose
controller (or, without one, its plant) is each representative (:func:`by_scenario`).
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path
from typing import Any

import pytest

from tests.scenario_groups import fmu_pair

# one model per family of code (plants: its physics; controllers: its law's C and Python
# family), each named with what it stands for
REPRESENTATIVES: dict[str, str] = {
    "BrakeDelayTrain": "one-mass plant, lag and dead-time brake, random resistance (seed 000)",
    "Emu3": "chain of power units with couplers (seeds 001, 003, 004)",
    "FreightTrain": "109 vehicles, air-brake wave, the compiled kernel (seed 002)",
    "StopPid": "periodic controller, bundled route grades (seed 000)",
    "StopRsmpc": "self-triggered predictive controller, DAQP's QP (seed 000)",
    "EmuIsmpc3": "data-driven family: FFDL model, sliding surface, QP (seed 001)",
    "FreightPreview": "freight tracker family: observer and reference blending (seed 002)",
    "Crh3Gpc": "GPC on an eco profile generated at instantiation (seed 003)",
    "Gmpc3": "hybrid MIQP (DAQP's branch and bound) on a time profile (seed 004)",
}


def by_model(identifiers: Iterable[str]) -> list[Any]:
    """``identifiers`` as pytest parameters: a representative in the default suite, the
    others marked slow."""
    return [pytest.param(i, id=i, marks=() if i in REPRESENTATIVES else pytest.mark.slow)
            for i in identifiers]


def _lead_fmu(name: str) -> str:
    """The FMU of the shipped scenario ``name``'s controller, else its plant
    (:func:`scenario_groups.fmu_pair`)."""
    roles = dict(item.split("=", 1) for item in fmu_pair(name))
    return roles.get("controller") or roles.get("plant", "")


def by_scenario(paths: Iterable[Path]) -> list[Any]:
    """Scenario files as pytest parameters (id: the stem): the first of those whose
    controller (else plant) is a given representative in the default suite, the others
    marked slow."""
    seen: set[str] = set()
    out = []
    for path in paths:
        lead = _lead_fmu(path.stem)
        sample = lead in REPRESENTATIVES and lead not in seen
        seen.add(lead)
        out.append(pytest.param(path, id=path.stem, marks=() if sample else pytest.mark.slow))
    return out
