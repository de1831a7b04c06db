"""Which builds of the catalog FMUs a reproduction runs on (``cosim reproduce --build``): the
overrides that select the native C builds, and the refusal of a rounding rerun a native build
cannot perturb."""

from __future__ import annotations

import functools

from cosim.build.native import NATIVE
from cosim.reproduce.entry import Entry, ReproduceError
from cosim.reproduce.record import Overrides
from cosim.run.scenario import load_scenario

BUILDS = ("native", "python")  # --build: the catalog FMUs' native C builds where they exist


@functools.lru_cache(maxsize=256)
def _components(scenario: str, fmus: tuple[tuple[str, str], ...]
                ) -> tuple[tuple[str, str, str], ...]:
    """(name, catalog identifier, build) of each FMU of ``scenario`` with its ``.fmu`` and
    ``.build`` overrides ``fmus``."""
    sc = load_scenario(scenario, dict(fmus))
    return tuple((c.name, c.fmu, c.build) for c in sc.components.values())


def _fmu_overrides(overrides: Overrides) -> tuple[tuple[str, str], ...]:
    return tuple(sorted((k, v) for k, v in overrides.items() if k.endswith((".fmu", ".build"))))


def runs_a_python_build(scenario: str, overrides: Overrides) -> bool:
    """Whether ``scenario`` with ``overrides`` runs an FMU on its Python build (one not set to
    ``build = "native"``)."""
    return any(built != "native" for _n, _f, built in
               _components(scenario, _fmu_overrides(overrides)))


def build_overrides(scenario: str, overrides: Overrides, build: str) -> dict[str, str]:
    """The overrides that run ``scenario`` (with ``overrides``) on ``build``: with "native",
    ``NAME.build = "native"`` for every FMU whose catalog identifier has a native C model
    (:data:`cosim.build.native.NATIVE`; the others stay Python) and whose build
    ``overrides`` do not set; with "python" none."""
    if build not in BUILDS:
        raise ReproduceError(f"--build {build}: one of {', '.join(BUILDS)}")
    if build == "python":
        return {}
    return {f"{name}.build": "native"
            for name, fmu, _built in _components(scenario, _fmu_overrides(overrides))
            if fmu in NATIVE and f"{name}.build" not in overrides}


def check_rounding_path(entry: Entry, builds: dict[str, dict[str, str]]) -> None:
    """Refuse a rounding rerun that would repeat the main run: a native C FMU has no numpy
    reference path, so where a run has one, ``[ensemble] rounding_perturb`` must name a
    parameter to perturb (``builds``: run name -> :func:`build_overrides`)."""
    native = sorted(name for name, over in builds.items() if over)
    if native and not entry.ensemble.rounding_perturb:
        raise ReproduceError(
            f"{entry.path}: [ensemble] rounding_perturb: empty, but runs {native[:3]} use "
            "native C builds, which have no numpy reference path: name a parameter to "
            "perturb by 1e-12 (or run with --build python, or --no-rounding)")
