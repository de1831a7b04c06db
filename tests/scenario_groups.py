"""One shipped scenario per pair of FMUs, for the whole-run tests.

The tests that compare two ways of running the same FMUs over a scenario (the FMI 3.0 builds
against the FMI 2.0 builds, libcosim against our master, a native plant against its Python
core) run the first seconds of every shipped scenario (in the default suite, or of a sample of
them: :mod:`matrix`), and whole runs
(``slow``) of one scenario per (plant FMU, controller FMU) pair: the scenarios of one pair
differ only in parameter values and reference data, which both compared paths pass to the
same code unchanged, so a whole run per pair covers every code path a whole run can reach
that the short runs cannot (late events, stops, long horizons). The representative of a pair
is its first scenario in name order.
"""

from __future__ import annotations

from functools import cache

from cosim.run.scenario import load_scenario, scenario_files


@cache
def fmu_pair(name: str) -> tuple[str, ...]:
    """The FMU of each component of the shipped scenario ``name``, in component order."""
    scenario = load_scenario(name)
    return tuple(f"{role}={c.fmu_path.stem}" for role, c in scenario.components.items())


def one_per_fmu_pair(names: list[str] | None = None) -> list[str]:
    """The first (in name order) of ``names`` (default: every shipped scenario) for each
    distinct :func:`fmu_pair`."""
    chosen: dict[tuple[str, ...], str] = {}
    for name in sorted(names if names is not None
                       else (scenario_files())):
        chosen.setdefault(fmu_pair(name), name)
    return sorted(chosen.values())
