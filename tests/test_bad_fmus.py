"""FMU files that are not usable FMUs: a clear error naming the scenario file, the instance and
the path (run), and checks that could not run reported as skipped, never ok (validate)."""

from __future__ import annotations

import zipfile
from pathlib import Path

import pytest

from cosim.interop.compliance import ALL_CHECKS, SKIPPED, check_fmu, format_report
from cosim.run import archive
from cosim.run.scenario import ScenarioError, find_scenario
from cosim.run.simulate import run_scenario


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
    text = (find_scenario("seed000_stop_pid")).read_text()
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


def with_zeros(tmp: Path, ours: Path, size: int) -> Path:
    """Our StopPid with ``size`` zero bytes more in resources/ (they deflate to ~1/1000)."""
    path = tmp / "padded.fmu"
    with zipfile.ZipFile(ours) as src, zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as dst:
        for item in src.infolist():
            dst.writestr(item, src.read(item))
        dst.writestr("resources/zeros.bin", bytes(size))
    return path


@pytest.mark.parametrize("variable,value,says", [
    ("COSIM_MAX_EXTRACTED_MB", "16", "expands to {expanded}, more than the limit of 16 MiB "
     "\\(raise it with COSIM_MAX_EXTRACTED_MB=MIB in the environment"),
    ("COSIM_MAX_FILES", "3", "files in the archive, more than the limit of 3 \\(raise it with "
     "COSIM_MAX_FILES=N in the environment"),
    ("COSIM_MAX_MODEL_DESCRIPTION_MB", "0.001", "modelDescription.xml is .* more than the "
     "limit of 1.02 KiB \\(raise it with COSIM_MAX_MODEL_DESCRIPTION_MB=MIB"),
    ("COSIM_MAX_FILES", "many", "environment variable COSIM_MAX_FILES='many': expected a "
     "positive number"),
])
def test_run_bounds_an_fmu_archive_before_extracting_it(built_fmus, tmp_path, monkeypatch,
                                                         variable, value, says):
    import re
    import tempfile

    ours = built_fmus["StopPid"].path
    fmu = with_zeros(tmp_path, ours, 64 << 20)  # 64 MiB more, about 64 KiB more in the zip
    assert fmu.stat().st_size < ours.stat().st_size + (1 << 20)
    scenario = scenario_with(tmp_path, fmu)
    temp = tmp_path / "temp"
    temp.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(temp))
    monkeypatch.setenv(variable, value)
    with pytest.raises(ScenarioError) as err:
        run_scenario(scenario, build=False, out_dir=tmp_path / "out")
    message = str(err.value)
    # the first FMU of the scenario that breaks the limit is named
    assert re.match(rf"{re.escape(str(scenario))}: \[fmus\.\w+\] fmu = '[^']+': refused before "
                    "extraction: ", message), message
    with zipfile.ZipFile(fmu) as z:  # what the padded archive expands to, as the message says
        expanded = archive._size(sum(e.file_size for e in z.infolist()))
    assert re.search(says.replace("{expanded}", re.escape(expanded)), message), message
    # the refused FMU is not extracted (FMUs before it in the scenario may be)
    assert not any((folder / "resources" / "zeros.bin").exists() for folder in temp.iterdir())
