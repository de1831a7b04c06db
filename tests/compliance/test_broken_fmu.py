"""The compliance suite itself: a deliberately broken FMU fails it, check by check, with
messages that say what is wrong; crashes and hangs are reported instead of killing pytest."""

from __future__ import annotations

import zipfile

import pytest

from cosim.interop.compliance import ERROR, check_fmu, format_report, passed

PLANTED = {  # check -> fragment of the expected message (see broken_train.py)
    "fmpy-validation": "InitialUnknowns",
    "units": "without a unit",
    "model-structure": "no dependencies attribute",
    "default-experiment": "no DefaultExperiment",
    "reset": "after fmi2Reset differs",
    "fmu-state": "after fmi2SetFMUstate the rest of the run differs",
    "two-instances": "differs from a run alone",
    "wrong-state": "fmi2DoStep before initialisation: accepted",
    "non-finite-inputs": "input u = nan: accepted",
    "invalid-step": "crashed (SIGABRT) in fmi2DoStep(currentCommunicationPoint=",
    "bad-parameters": "hang: fmi2SetReal(",
}


def test_broken_fmu_fails(broken_results):
    assert not passed(broken_results)


@pytest.mark.parametrize("check", sorted(PLANTED))
def test_planted_fault_reported(check, broken_results, broken_fmu):
    messages = [p.message for p in broken_results if p.check == check and p.severity == ERROR]
    assert any(PLANTED[check] in m for m in messages), format_report(broken_fmu, broken_results)


def test_fatal_rejection_is_an_error(broken_results, broken_fmu):
    """Plain pythonfmu turns the planted exception (doStep after terminate) into fmi2Fatal:
    an error that names the call, the expected status and the cause."""
    messages = [p.message for p in broken_results
                if p.check == "wrong-state" and p.severity == ERROR]
    assert any("fmi2DoStep after fmi2Terminate: rejected with fmi2Fatal, expected fmi2Error"
               in m and "pythonfmu" in m for m in messages), format_report(broken_fmu,
                                                                           broken_results)


def test_sound_parts_of_broken_fmu_pass(broken_results):
    """No false alarms: the calling sequence itself works and v does not feed through."""
    flagged = {p.check for p in broken_results if p.severity == ERROR}
    assert not flagged & {"calling-sequence", "output-dependencies", "variables"}


def test_report_is_readable(broken_results, broken_fmu):
    report = format_report(broken_fmu, broken_results)
    assert "FAIL  reset" in report and "ok    calling-sequence" in report
    assert report.rstrip().endswith(f"FAILED: {sum(p.severity == ERROR for p in broken_results)}"
                                    " error(s), 0 warning(s)")


def test_not_an_fmu(tmp_path):
    missing = check_fmu(tmp_path / "nothing.fmu")
    assert not passed(missing) and "no such file" in missing[0].message
    junk = tmp_path / "junk.fmu"
    with zipfile.ZipFile(junk, "w") as z:
        z.writestr("readme.txt", "not an FMU")
    assert not passed(check_fmu(junk))


def test_misdeclared_feedthrough_is_caught(built_fmus, tmp_path):
    """StopPid with its ModelStructure edited to claim that brake_command does not depend on
    the inputs: the dynamic check sees the output move when an input changes."""
    source = built_fmus["StopPid"].path
    target = tmp_path / "StopPidMisdeclared.fmu"
    with zipfile.ZipFile(source) as zin, zipfile.ZipFile(target, "w") as zout:
        for item in zin.infolist():
            data = zin.read(item.filename)
            if item.filename == "modelDescription.xml":
                text = data.decode()
                index = _index_of(text, "brake_command")
                text = _empty_dependencies(text, index)
                data = text.encode()
            zout.writestr(item, data)
    problems = [p for p in check_fmu(target) if p.check == "output-dependencies"]
    assert any("brake_command changed when the inputs changed" in p.message for p in problems)


def _index_of(xml: str, name: str) -> int:
    from xml.etree import ElementTree

    names = [sv.get("name") for sv in ElementTree.fromstring(xml).find("ModelVariables")]
    return names.index(name) + 1


def _empty_dependencies(xml: str, index: int) -> str:
    import re

    pattern = rf'(<Unknown index="{index}" dependencies=")[^"]*(")'
    edited, n = re.subn(pattern, r"\g<1>\g<2>", xml, count=1)
    assert n == 1
    return edited
