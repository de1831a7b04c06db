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
    passed,
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


def validate(*args: str) -> subprocess.CompletedProcess:
    """``cosim validate ARGS`` as a process (its exit status is what these tests read)."""
    return subprocess.run([sys.executable, "-m", "cosim.cli", "validate", *args],
                          capture_output=True, text=True, timeout=300)


@pytest.fixture(scope="module")
def alltypes_strict(c_fmus) -> subprocess.CompletedProcess:
    """The finished ``cosim validate AllTypes.fmu --call-timeout 1`` (strict, the default)."""
    return validate(str(c_fmus["AllTypes"]), "--call-timeout", str(CALL_TIMEOUT))


def test_cli_lenient_exit_status(c_fmus, alltypes_strict):
    """``cosim validate --lenient`` exits with 0 on AllTypes, the strict check with 1."""
    done = validate(str(c_fmus["AllTypes"]), "--lenient")
    assert done.returncode == 0, done.stdout
    assert "warning (recommended): input u = nan: accepted" in done.stdout
    assert "[FMI 2.0.4 2.1.7" in done.stdout and "PASSED: 0 error(s)" in done.stdout
    done = alltypes_strict
    assert done.returncode == 1 and "FAILED" in done.stdout


def test_strict_report_of_a_third_party_fmu_suggests_lenient(alltypes_strict, results):
    """AllTypes fails the strict checks only on what the standard leaves to the FMU."""
    done = alltypes_strict
    assert done.returncode == 1
    assert ("hint: every error above is something FMI recommends or leaves to the FMU, or a "
            "convention of this project; for a third-party FMU, --lenient checks only what the "
            "standard requires (it passes this one)") in done.stdout, done.stdout
    # a required rule broken: lenient fails it too, so no such hint
    assert not passed(results("FeedthroughLying", False))


def test_strict_report_with_a_required_rule_broken_counts_what_lenient_keeps(c_fmus, results):
    """FeedthroughLying breaks a required rule and fails on what the standard leaves to the
    FMU: the strict report says how many of its errors --lenient would keep."""
    errors = sum(p.severity == ERROR for p in results("FeedthroughLying", True))
    remain = sum(p.severity == ERROR for p in results("FeedthroughLying", False))
    assert 0 < remain < errors
    done = subprocess.run([sys.executable, "-m", "cosim.cli", "validate",
                           str(c_fmus["FeedthroughLying"]), "--call-timeout", str(CALL_TIMEOUT)],
                          capture_output=True, text=True)
    assert done.returncode == 1
    assert (f"hint: {errors - remain} of the {errors} errors above are what FMI recommends or "
            "leaves to the FMU, or conventions of this project; for a third-party FMU, "
            f"--lenient checks only what the standard requires ({remain} error(s) remain)"
            ) in done.stdout, done.stdout


def test_refused_event_mode_instantiation_says_what_the_fmu_said(c_fmus3, monkeypatch, tmp_path):
    """A binary that returns NULL for eventModeUsed = true: the report names the call, its
    arguments, why an importer may ask for it and the FMU's own message, not fmpy's "Failed to
    instantiate model"."""
    from fmpy import extract
    from fmpy.fmi3 import FMU3Slave

    from cosim.interop.compliance.fmi3 import _Failed3, _Host3

    def refusing(self, visible=False, loggingOn=False, eventModeUsed=False, **kw):
        kw["logMessage"](None, 3, b"logStatusError", b"Event Mode is not supported")
        raise Exception("Failed to instantiate model")

    path = c_fmus3["TimeEvents3"]
    host = _Host3(path, str(extract(str(path), tmp_path / "unzipped")), 8)
    monkeypatch.setattr(FMU3Slave, "instantiate", refusing)
    with pytest.raises(_Failed3) as err:
        host.instance("events", eventModeUsed=True)
    assert str(err.value) == (
        "fmi3InstantiateCoSimulation(eventModeUsed=True) returned NULL (its modelDescription "
        "declares hasEventMode = true, so an importer may ask for Event Mode); FMU says: Event "
        "Mode is not supported")


def test_fmi3_step_without_a_default_stays_near_the_internal_step(c_fmus3, tmp_path):
    """No DefaultExperiment stepSize, stopTime 1e7 s, fixedInternalStepSize 1e-3 s (as the
    Reference Roberts): the checks step 100 internal steps (0.1 s), not 1e7 / 100 s (1e8
    internal steps in one fmi3DoStep, a false hang)."""
    import re
    import zipfile

    from fmpy import extract

    from cosim.interop.compliance.fmi3 import _Host3

    src, path = c_fmus3["TimeEvents3"], tmp_path / "LongSpan.fmu"
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(path, "w") as zout:
        for item in zin.infolist():
            data = zin.read(item)
            if item.filename == "modelDescription.xml":
                text = re.sub(r"<DefaultExperiment[^>]*/>",
                              '<DefaultExperiment startTime="0" stopTime="1e7"/>', data.decode())
                text = text.replace("<CoSimulation ",
                                    '<CoSimulation fixedInternalStepSize="1e-3" ')
                data = text.encode()
            zout.writestr(item, data)
    host = _Host3(path, str(extract(str(path), tmp_path / "unzipped")), 40)
    assert host.h == 100 * 1e-3
