"""``cosim validate`` on the third-party C FMUs: every finding names its FMI 2.0.4 clause; the
FMUs follow what the standard requires, so ``--lenient`` passes them (what they leave out is
recommended or our convention: warnings), while the strict mode (ours) fails them on exactly
those checks; a broken required rule stays an error; a hanging call is reported with its
arguments within the per-call limit."""

from __future__ import annotations

import subprocess
import sys

import pytest

from cosim.interop.compliance import (
    ALL_CHECKS,
    CLAUSES,
    ERROR,
    REQUIRED,
    WARNING,
    Options,
    check_fmu,
    classify,
)

# the C FMUs accept NaN/out-of-range parameters and NaN inputs and a fixed parameter set after
# initialisation: the standard leaves these to the FMU
LEFT_TO_FMU = {"wrong-state", "non-finite-inputs", "bad-parameters"}
STRICT_ERRORS = {
    "AllTypes": LEFT_TO_FMU,
    "Terminator": {"wrong-state", "bad-parameters", "variable-step"},  # `steps` counts doSteps
    "Discarder": LEFT_TO_FMU,
    "DiscarderFixed": LEFT_TO_FMU | {"capabilities"},  # no variable steps: checks skipped
    "Feedthrough": LEFT_TO_FMU,
    "FeedthroughUndeclared": LEFT_TO_FMU | {"model-structure"},  # no dependencies attribute
    "Events": LEFT_TO_FMU,
    "FeedthroughLying": LEFT_TO_FMU | {"output-dependencies"},
    "Hanger": LEFT_TO_FMU | {"invalid-step"},
}
LENIENT_ERRORS = {"FeedthroughLying": {"output-dependencies"}}  # declared independent: wrong
CALL_TIMEOUT = 1.0

_results: dict[str, list] = {}


@pytest.fixture
def results(c_fmus):
    """Findings of one FMU, strict or lenient; the checks run once per FMU (lenient verdicts
    are the strict findings classified again: only non-required errors change)."""
    def get(name: str, strict: bool) -> list:
        if name not in _results:
            _results[name] = check_fmu(c_fmus[name], Options(call_timeout=CALL_TIMEOUT))
        return _results[name] if strict else classify(_results[name], strict=False)
    return get


@pytest.mark.parametrize("name", sorted(STRICT_ERRORS))
def test_verdicts_follow_the_standard(results, name):
    strict, lenient = results(name, True), results(name, False)
    assert {p.check for p in strict if p.severity == ERROR} == STRICT_ERRORS[name]
    assert {p.check for p in lenient if p.severity == ERROR} == LENIENT_ERRORS.get(name, set())
    for p in lenient:  # what is not an error is a warning because the standard allows it
        assert p.clause, p
        if p.severity == WARNING and p.check in STRICT_ERRORS[name]:
            assert p.requirement != REQUIRED, p


def test_every_check_names_its_clause():
    assert set(ALL_CHECKS) <= set(CLAUSES)
    assert all(clause and requirement for clause, requirement in CLAUSES.values())


def test_hanging_call_is_reported_with_its_arguments(results):
    hangs = [p for p in results("Hanger", False) if "did not return" in p.message]
    assert len(hangs) == 1 and hangs[0].check == "invalid-step"
    assert hangs[0].message.startswith(
        "hang: fmi2DoStep(currentCommunicationPoint=0.0, communicationStepSize=nan) did not "
        "return: it used "), hangs[0].message
    assert f"over its limit of {CALL_TIMEOUT:g} CPU s" in hangs[0].message
    assert hangs[0].severity == WARNING  # a NaN step size is the master's error (4.2.2)
    # the worker restarted: the checks after the hang ran
    assert any(p.check == "bad-parameters" for p in results("Hanger", False))


def test_cli_lenient_exit_status(c_fmus):
    def validate(*args: str) -> subprocess.CompletedProcess:
        return subprocess.run([sys.executable, "-m", "cosim.cli", "validate", *args],
                              capture_output=True, text=True, timeout=300)

    done = validate(str(c_fmus["AllTypes"]), "--lenient")
    assert done.returncode == 0, done.stdout
    assert "warning (recommended): input u = nan: accepted" in done.stdout
    assert "[FMI 2.0.4 2.1.7" in done.stdout and "PASSED: 0 error(s)" in done.stdout
    done = validate(str(c_fmus["AllTypes"]))
    assert done.returncode == 1 and "FAILED" in done.stdout
