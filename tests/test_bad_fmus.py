"""FMU files that are not usable FMUs: a clear error naming the scenario file, the instance and
the path (run), and checks that could not run reported as skipped, never ok (validate)."""

from __future__ import annotations

import zipfile
from pathlib import Path

import pytest

from cosim.interop.compliance import ALL_CHECKS, SKIPPED, check_fmu, format_report
from cosim.run.master import run_scenario
from cosim.run.scenario import SCENARIO_DIR, ScenarioError


def corrupt(tmp: Path) -> Path:
    path = tmp / "random.fmu"
    path.write_bytes(bytes(range(256)) * 20)  # not a zip archive
    return path


def without_model_description(tmp: Path) -> Path:
    path = tmp / "nomd.fmu"
    with zipfile.ZipFile(path, "w") as z:
        z.writestr("resources/readme.txt", "no modelDescription.xml here")
    return path


def other_platform(tmp: Path, ours: Path) -> Path:
    """Our StopPid with its linux64 binary left out (as if built for Windows only)."""
    path = tmp / "win_only.fmu"
    with zipfile.ZipFile(ours) as src, zipfile.ZipFile(path, "w") as dst:
        for item in src.infolist():
            if not item.filename.startswith("binaries/linux64/"):
                dst.writestr(item, src.read(item))
    return path


def renamed_library(tmp: Path, ours: Path) -> Path:
    """Our StopPid with its linux64 library under another name than its modelIdentifier."""
    path = tmp / "renamed.fmu"
    with zipfile.ZipFile(ours) as src, zipfile.ZipFile(path, "w") as dst:
        for item in src.infolist():
            data = src.read(item)
            if item.filename == "binaries/linux64/StopPid.so":
                item.filename = "binaries/linux64/Other.so"
            dst.writestr(item, data)
    return path


def scenario_with(tmp: Path, fmu: Path) -> Path:
    text = (SCENARIO_DIR / "seed000_stop_pid.toml").read_text()
    text = text.replace('fmu = "StopPid"', f'fmu = "{fmu}"')
    path = tmp / "bad.toml"
    path.write_text(text)
    return path


@pytest.mark.parametrize("make,says", [
    (lambda tmp, _: corrupt(tmp), "not an FMU (not a readable zip archive"),
    (lambda tmp, _: without_model_description(tmp), "no modelDescription.xml"),
    (lambda tmp, ours: other_platform(tmp, ours), "no binary for this platform (linux64; "
                                                   "the FMU has win64)"),
    (lambda tmp, ours: renamed_library(tmp, ours), "binaries/linux64/ has no StopPid.so, the "
     "library of modelIdentifier 'StopPid' in modelDescription.xml (it holds Other.so"),
])
def test_scenario_naming_a_bad_fmu_is_a_clear_error(built_fmus, tmp_path, make, says):
    fmu = make(tmp_path, built_fmus["StopPid"].path)
    scenario = scenario_with(tmp_path, fmu)
    with pytest.raises(ScenarioError) as err:
        run_scenario(scenario, build=False, out_dir=tmp_path / "out")
    message = str(err.value)
    assert message.startswith(f"{scenario}: [fmus.controller] fmu = '{fmu}': "), message
    assert says in message
    assert not (tmp_path / "out").exists()  # nothing ran


@pytest.mark.parametrize("make", [corrupt, without_model_description])
def test_validate_reports_checks_that_could_not_run_as_skipped(tmp_path, make):
    path = make(tmp_path)
    problems = check_fmu(path)
    report = format_report(path, problems)
    lines = [line.split() for line in report.splitlines()[1:-1] if not line.startswith(" " * 6)]
    labels = {words[1]: words[0] for words in lines}
    assert set(labels) == set(ALL_CHECKS)
    assert "ok" not in labels.values(), report
    assert labels["fmpy-validation"] == "FAIL"
    assert {p.check for p in problems if p.severity == SKIPPED} >= {"units", "reset",
                                                                     "fmu-state"}
    assert "skipped" in report.splitlines()[-1]
