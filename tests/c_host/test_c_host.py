"""A C program (gcc + fmpy's FMI 2 headers) runs one of our FMUs: the way any non-Python tool
loads them (docs/other_tools.md). Its results equal fmpy's for the same calls."""

from __future__ import annotations

import os
import shutil
import site
import subprocess
import sysconfig
from pathlib import Path

import fmpy
import numpy as np
import pytest
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave

HERE = Path(__file__).resolve().parent
STEP, N_STEPS, COMMAND = 0.2, 25, 50.0
OUTPUTS = ("v", "s", "a_c")


def libpython() -> Path:
    """The shared libpython of this interpreter (what a host must load before the FMU)."""
    libdir, name = sysconfig.get_config_var("LIBDIR"), sysconfig.get_config_var("LDLIBRARY")
    return Path(libdir) / name


@pytest.fixture(scope="module")
def host(tmp_path_factory) -> Path:
    if shutil.which("gcc") is None:
        pytest.skip("gcc not installed")
    exe = tmp_path_factory.mktemp("c_host") / "fmu_host"
    headers = Path(fmpy.__file__).parent / "c-code"
    subprocess.run(["gcc", "-std=c99", "-D_DEFAULT_SOURCE", "-Wall", "-Wextra", "-Werror",
                    "-O1", f"-I{headers}", "-o", str(exe), str(HERE / "fmu_host.c"), "-ldl"],
                   check=True, capture_output=True, text=True)
    return exe


@pytest.fixture(scope="module")
def plant(built_fmus, tmp_path_factory):
    path = built_fmus["BrakeDelayTrain"].path
    md = read_model_description(str(path))
    unzipdir = extract(str(path), unzipdir=str(tmp_path_factory.mktemp("fmu")))
    return path, md, unzipdir


def run_host(host: Path, plant, preload: bool) -> subprocess.CompletedProcess:
    _, md, unzipdir = plant
    vr = {v.name: v.valueReference for v in md.modelVariables}
    env = {k: v for k, v in os.environ.items() if k not in ("LD_PRELOAD", "PYTHONHOME")}
    # the FMU's Python packages (pythonfmu, numpy) must be importable by the embedded
    # interpreter: this interpreter's site-packages (a virtual environment's included)
    env["PYTHONPATH"] = os.pathsep.join([*site.getsitepackages(), env.get("PYTHONPATH", "")])
    if preload:
        env["LD_PRELOAD"] = str(libpython())
    args = [str(host), unzipdir, md.coSimulation.modelIdentifier, md.guid, repr(STEP),
            str(N_STEPS), f"in:{vr['brake_command']}={COMMAND}",
            *[f"out:{vr[name]}" for name in OUTPUTS]]
    return subprocess.run(args, capture_output=True, text=True, timeout=120, env=env)


def fmpy_reference(plant) -> np.ndarray:
    _, md, unzipdir = plant
    vr = {v.name: v.valueReference for v in md.modelVariables}
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzipdir, instanceName="reference",
                    modelIdentifier=md.coSimulation.modelIdentifier)
    fmu.instantiate()
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.setReal([vr["brake_command"]], [COMMAND])
    fmu.exitInitializationMode()
    rows = []
    for k in range(N_STEPS):
        fmu.doStep(currentCommunicationPoint=k * STEP, communicationStepSize=STEP)
        rows.append([(k + 1) * STEP, *fmu.getReal([vr[n] for n in OUTPUTS])])
    fmu.terminate()
    fmu.freeInstance()
    return np.array(rows)


def test_c_host_runs_fmu_like_fmpy(host, plant):
    done = run_host(host, plant, preload=True)
    assert done.returncode == 0, done.stderr
    rows = np.array([[float(x) for x in line.split(",")] for line in done.stdout.split()])
    assert rows.shape == (N_STEPS, 1 + len(OUTPUTS))
    np.testing.assert_allclose(rows, fmpy_reference(plant), rtol=1e-15, atol=1e-12)
    assert rows[-1, 1] < rows[0, 1]  # the brake command slowed the train


def test_c_host_needs_libpython_loaded_first(host, plant):
    """Without libpython in the global symbol scope the FMU binary does not load: this is why
    hosts need LD_PRELOAD (or to link or dlopen libpython with RTLD_GLOBAL themselves)."""
    done = run_host(host, plant, preload=False)
    assert done.returncode == 2
    assert "undefined symbol" in done.stderr and "Py" in done.stderr
