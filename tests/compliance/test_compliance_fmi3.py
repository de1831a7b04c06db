"""FMI 3.0 compliance (cosim.interop.compliance.fmi3) of every FMU's FMI 3 build, and the
static checks finding faults planted in a copy of one."""

from __future__ import annotations

import re
import shutil
import zipfile
from pathlib import Path

import pytest

from cosim.build.python import catalog
from cosim.interop.compliance import (
    ERROR,
    FMI3_CHECKS,
    Options,
    check_fmu,
    checks_for,
    format_report,
    passed,
)
from tests.matrix import by_model

IDENTIFIERS = sorted(catalog())


@pytest.fixture(scope="session")
def fmi3_results(built_fmus_fmi3, checked_once):
    """identifier -> problems of its FMI 3 build, computed once per FMU and test run."""
    return lambda identifier: checked_once(built_fmus_fmi3[identifier].path_fmi3)


@pytest.mark.parametrize("check", FMI3_CHECKS)
@pytest.mark.parametrize("identifier", by_model(IDENTIFIERS))
def test_fmi3_build_passes_check(identifier, check, fmi3_results, built_fmus_fmi3):
    problems = fmi3_results(identifier)
    errors = [p for p in problems if p.check == check and p.severity == ERROR]
    assert not errors, format_report(built_fmus_fmi3[identifier].path_fmi3, problems)
    # every finding belongs to a check of the parametrisation (so none goes unseen)
    assert {p.check for p in problems} <= set(FMI3_CHECKS), problems


def test_fmi3_checks_are_chosen_by_fmi_version(built_fmus_fmi3):
    spec = built_fmus_fmi3["StopPid"]
    assert checks_for(spec.path_fmi3) == FMI3_CHECKS
    assert not set(checks_for(spec.path)) & set(FMI3_CHECKS)


def _planted(src: Path, dest: Path, edit) -> Path:
    """A copy of ``src`` whose modelDescription.xml is ``edit(text)``."""
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dest, "w") as zout:
        for item in zin.infolist():
            data = zin.read(item)
            if item.filename == "modelDescription.xml":
                data = edit(data.decode()).encode()
            zout.writestr(item, data)
    return dest


FAULTS = {
    # name: (edit, check that must fail, words of its message)
    "no independent variable": (lambda t: re.sub(r'<Float64 name="time"[^>]*/>', "", t),
                                "fmi3-variables", "independent"),
    "output not in ModelStructure": (lambda t: re.sub(r'<Output valueReference="\d+"'
                                                      r'[^>]*/>', "", t, count=1),
                                     "fmi3-model-structure", "not listed"),
    "start above max": (lambda t: t.replace('min="1e-06" start="0.5"',
                                            'min="1e-06" max="0.1" start="0.5"'),
                        "fmi3-variables", "outside"),
    "input without start": (lambda t: re.sub(r'(causality="input"[^>]*?) start="[^"]*"', r"\1",
                                             t, count=1),
                            "fmi3-variables", "start value is required"),
}


@pytest.mark.parametrize("fault", sorted(FAULTS))
def test_static_fmi3_checks_find_planted_faults(fault, built_fmus_fmi3, tmp_path):
    edit, check, words = FAULTS[fault]
    src = built_fmus_fmi3["StopPid"].path_fmi3
    with zipfile.ZipFile(src) as z:
        original = z.read("modelDescription.xml").decode()
    assert edit(original) != original, "the edit must change the modelDescription"
    path = _planted(src, tmp_path / "Planted.fmu", edit)
    for strict in (True, False):  # required by the standard: an error even when lenient
        problems = check_fmu(path, Options(strict=strict, dynamic=False))
        found = [p for p in problems if p.check == check and p.severity == ERROR]
        assert found and any(words in p.message for p in found), problems
        assert not passed(problems)
    report = format_report(path, problems)
    assert f"FAIL  {check}" in report and "[FMI 3.0 2.4 (" in report


def test_copied_fmi3_build_still_passes_the_static_checks(built_fmus_fmi3, tmp_path):
    copy = tmp_path / "StopPid.fmu"
    shutil.copy2(built_fmus_fmi3["StopPid"].path_fmi3, copy)
    assert passed(check_fmu(copy, Options(dynamic=False)))
