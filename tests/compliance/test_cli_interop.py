"""`cosim validate` on a broken third-party FMU and on unknown names; `cosim export --ssp`.
(`cosim validate` passing ours: test_cli.test_list_and_validate.) Refusals are read in this
process through typer's test runner."""

from __future__ import annotations

import json
import subprocess
import sys

from fmpy.ssp.ssd import read_ssd

from tests.cli_inproc import cosim_inproc


def cosim(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "cosim.cli", *args], capture_output=True,
                          text=True, timeout=600)


def test_validate_fails_broken_fmu_with_readable_report(broken_fmu):
    done = cosim("validate", str(broken_fmu), "--json", "--call-timeout", "1")
    assert done.returncode == 1
    report = json.loads(done.stdout)[str(broken_fmu)]
    assert {"reset", "fmu-state", "wrong-state"} <= {p["check"] for p in report
                                                    if p["severity"] == "error"}


def test_validate_unknown_fmu_is_an_error():
    done = cosim_inproc("validate", "NoSuchFmu")
    assert done.exit_code == 2 and "unknown FMU" in done.stderr
    typo = cosim_inproc("validate", "StopPd")
    assert typo.exit_code == 2
    assert "unknown FMU 'StopPd' (did you mean 'StopPid'?)" in typo.stderr.replace("\n", " ")


def test_export_ssp(tmp_path, built_fmus):
    target = tmp_path / "pid.ssp"
    done = cosim("export", "seed000_stop_pid", "--ssp", str(target), "--set", "plant.mass=539000")
    assert done.returncode == 0, done.stderr
    ssd = read_ssd(str(target), validate=True)
    plant = next(e for e in ssd.system.elements if e.name == "plant")
    values = {p.name: p.value for b in plant.parameterBindings for s in b.parameterValues
              for p in s.parameters}
    assert float(values["mass"]) == 539000.0
    bad = cosim_inproc("export", "no_such_scenario", "--ssp", str(tmp_path / "x.ssp"))
    assert bad.exit_code == 2 and "no such scenario" in bad.stderr
