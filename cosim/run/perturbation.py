"""The plant-mismatch syntax and its seeded draws, shared by ``cosim sweep --perturb``
(:mod:`cosim.run.perturb`) and a reproduction's ``[ensemble] perturb``
(:mod:`cosim.reproduce.ensemble`). Forms of ``KEY=SPEC``:

* ``+-10%``: uniform within 10 % of the nominal value (the scenario's, else the FMU's start);
* ``+-0.05``: uniform within 0.05 (in the parameter's unit) of the nominal value;
* ``0.3..0.6``: uniform in ``[0.3, 0.6]``.

Draws: ``numpy.random.default_rng(seed)``, one uniform per sample and key, keys in the order
given.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from cosim.run.master.loading import read_fmu
from cosim.run.scenario import ScenarioError, load_scenario


@dataclass(frozen=True)
class Perturbation:
    """One perturbed parameter: ``kind`` is "relative" (fraction), "absolute" or "range"."""

    key: str
    kind: str
    a: float  # relative/absolute: half-width; range: low
    b: float = math.nan  # range: high

    def interval(self, nominal: float | None) -> tuple[float, float]:
        if self.kind == "range":
            return self.a, self.b
        if nominal is None:
            raise ValueError(f"--perturb {self.key}: no nominal value to perturb around")
        half = abs(nominal) * self.a if self.kind == "relative" else self.a
        return nominal - half, nominal + half


def parse_perturb(items: Iterable[str]) -> list[Perturbation]:
    """``["plant.mass=+-10%", "plant.brake_delay=0.8..1.2"]`` -> perturbations (errors name the
    item)."""
    out: list[Perturbation] = []
    for item in items:
        key, sep, spec = item.partition("=")
        key, spec = key.strip(), spec.strip().replace(" ", "")
        if not sep or "." not in key or not spec:
            raise ValueError(f"--perturb {item!r}: expected FMU.PARAMETER=SPEC, e.g. "
                             f"plant.mass=+-10% or plant.brake_time_constant=0.3..0.6")
        try:
            if spec.startswith("+-") and spec.endswith("%"):
                p = Perturbation(key, "relative", float(spec[2:-1]) / 100.0)
            elif spec.startswith("+-"):
                p = Perturbation(key, "absolute", float(spec[2:]))
            elif ".." in spec:
                lo, _, hi = spec.partition("..")
                p = Perturbation(key, "range", float(lo), float(hi))
            else:
                raise ValueError
        except ValueError as err:
            raise ValueError(f"--perturb {item!r}: SPEC must be +-X%, +-X or LOW..HIGH") from err
        if p.kind != "range" and not p.a >= 0:
            raise ValueError(f"--perturb {item!r}: the half-width must be >= 0")
        if p.kind == "range" and not p.a <= p.b:
            raise ValueError(f"--perturb {item!r}: empty range {p.a}..{p.b}")
        if any(q.key == key for q in out):
            raise ValueError(f"--perturb {item!r}: {key} is perturbed twice")
        out.append(p)
    return out


def nominal_values(scenario: str | Path, keys: Sequence[str],
                   overrides: dict[str, Any] | None = None) -> dict[str, float | None]:
    """The value each ``FMU.parameter`` has in the scenario, else the start value of the FMU
    a job with ``overrides`` runs (their ``NAME.fmu`` and ``NAME.build`` choose it; other
    overrides are the job's, not the nominal plant)."""
    chosen = {k: v for k, v in (overrides or {}).items() if k.endswith((".fmu", ".build"))}
    sc = load_scenario(scenario, chosen)
    out: dict[str, float | None] = {}
    starts: dict[str, dict[str, Any]] = {}
    for key in keys:
        comp_name, _, name = key.partition(".")
        comp = sc.components.get(comp_name)
        if comp is None:
            raise ScenarioError(f"{sc.path}: --perturb {key}: no FMU named {comp_name!r} "
                                f"(scenario has {sorted(sc.components)})")
        if name in comp.parameters:
            out[key] = float(comp.parameters[name])
            continue
        if comp_name not in starts:
            md = read_fmu(sc, comp_name, comp.fmu_path)  # within the archive limits
            starts[comp_name] = {v.name: v.start for v in md.modelVariables}
        if name not in starts[comp_name]:
            raise ScenarioError(f"{sc.path}: --perturb {key}: {comp.fmu} has no variable "
                                f"{name!r}")
        start = starts[comp_name][name]
        out[key] = None if start is None else float(start)
    return out


def draw_samples(perts: Sequence[Perturbation], nominals: dict[str, float | None],
                 samples: int, seed: int) -> list[dict[str, float]]:
    """``samples`` dicts ``{key: value}``, uniform in each perturbation's interval."""
    if samples < 1:
        raise ValueError(f"--samples {samples}: must be >= 1")
    rng = np.random.default_rng(seed)
    intervals = [(p.key, *p.interval(nominals.get(p.key))) for p in perts]
    return [{key: float(rng.uniform(lo, hi)) for key, lo, hi in intervals}
            for _ in range(samples)]
