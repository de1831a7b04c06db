"""The default suite's sample of the per-model matrices (tests/matrix.py) names real models,
covers both builds' families, and leaves no model unchecked by the slow suite."""

from __future__ import annotations

from matrix import REPRESENTATIVES, by_model, by_scenario

from cosim.build.native import NATIVE
from cosim.build.python import catalog
from cosim.run.scenario import scenario_files


def _slow(param) -> bool:
    return any(mark.name == "slow" for mark in param.marks)


def test_every_representative_is_a_catalog_model_with_a_native_twin() -> None:
    assert set(REPRESENTATIVES) <= set(catalog())
    assert set(REPRESENTATIVES) <= set(NATIVE)  # the native matrices sample the same models


def test_the_sample_runs_each_representative_once_and_marks_every_other_case_slow() -> None:
    models = by_model(sorted(catalog()))
    assert {p.values[0] for p in models if not _slow(p)} == set(REPRESENTATIVES)
    assert {p.values[0] for p in models} == set(catalog())  # every model is still a case
    scenarios = by_scenario(scenario_files().values())
    sampled = [p.id for p in scenarios if not _slow(p)]
    assert len(sampled) == len(set(sampled)) >= 5
    assert len(scenarios) == len(scenario_files())
