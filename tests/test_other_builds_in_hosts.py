"""The FMI 3.0 builds and the native FMUs run where the FMI 2.0 builds do
(tests/test_fmus.py): ``fmpy.simulate_fmu`` with its default arguments, and at the FMU
Compliance Checker's step (stop time / 500, here twice the FMU's default step), where a
controller executes the events inside each step with the inputs held."""

from __future__ import annotations

import pytest
from fmpy import read_model_description, simulate_fmu
from matrix import by_model

from cosim.build.python import catalog

IDENTIFIERS = sorted(catalog())


def _checker_step(path: str) -> float:
    return 2.0 * float(read_model_description(path).defaultExperiment.stepSize)


@pytest.mark.parametrize("identifier", by_model(IDENTIFIERS))
def test_every_fmi3_build_runs_in_fmpy_with_default_arguments(built_fmus_fmi3, identifier):
    result = simulate_fmu(str(built_fmus_fmi3[identifier].path_fmi3))
    assert len(result) > 1


@pytest.mark.parametrize("identifier", by_model(IDENTIFIERS))
def test_every_fmi3_build_runs_at_the_compliance_checkers_step(built_fmus_fmi3, identifier):
    path = str(built_fmus_fmi3[identifier].path_fmi3)
    step = _checker_step(path)
    result = simulate_fmu(path, stop_time=500 * step, output_interval=step)
    assert len(result) == 501 and result["time"][-1] == pytest.approx(500 * step)


@pytest.fixture(scope="module")
def native_fmus(native_builds):
    """Every native FMU in both FMI versions (Linux binaries)."""
    from cosim.build.native import NATIVE

    return [path for name in sorted(NATIVE) for path in native_builds(name).values()]


def test_every_native_fmu_runs_in_fmpy_by_default_and_at_the_checkers_step(native_fmus):
    for path in map(str, native_fmus):
        assert len(simulate_fmu(path)) > 1
        step = _checker_step(path)
        result = simulate_fmu(path, stop_time=500 * step, output_interval=step)
        assert len(result) == 501
