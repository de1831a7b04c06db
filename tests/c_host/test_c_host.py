"""A C program (gcc + fmpy's FMI 2 headers) runs one of our FMUs: the way any non-Python tool
loads them (docs/other_tools.md). Its results equal fmpy's for the same calls, with or without
libpython preloaded (the FMU's shim loads it); pythonfmu's plain binary needs it preloaded."""

from __future__ import annotations

import os
import site
import subprocess
import sys
import sysconfig
from pathlib import Path

import numpy as np
import pytest
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave

from cosim.build.python import SHIM_SUFFIX, shim_binary
from tests.matrix import by_model

STEP, N_STEPS, COMMAND = 0.2, 25, 50.0
OUTPUTS = ("v", "s", "a_c")


def libpython() -> Path:
    """The shared libpython of this interpreter (what a host must load before the FMU)."""
    libdir, name = sysconfig.get_config_var("LIBDIR"), sysconfig.get_config_var("LDLIBRARY")
    return Path(libdir) / name


@pytest.fixture(scope="module")
def host(c_hosts) -> Path:
    """fmu_host.c compiled (the root conftest's ``c_hosts``)."""
    return c_hosts("fmu_host")


@pytest.fixture(scope="module")
def plant(built_fmus, tmp_path_factory):
    path = built_fmus["BrakeDelayTrain"].path
    md = read_model_description(str(path))
    unzipdir = extract(str(path), unzipdir=str(tmp_path_factory.mktemp("fmu")))
    return path, md, unzipdir


def run_host(host: Path, plant, preload: bool, pythonpath: bool = True,
             binary: str | None = None, plain_exit: bool = False) -> subprocess.CompletedProcess:
    """Run the C host on the plant; ``binary``: another binaries/linux64/<binary>.so;
    ``plain_exit``: leave main() normally (exit handlers run) instead of _exit()."""
    _, md, unzipdir = plant
    vr = {v.name: v.valueReference for v in md.modelVariables}
    env = {k: v for k, v in os.environ.items()
           if k not in ("LD_PRELOAD", "PYTHONHOME", "PYTHONPATH", "FMU_HOST_PLAIN_EXIT")}
    if plain_exit:
        env["FMU_HOST_PLAIN_EXIT"] = "1"
    if pythonpath:
        # the FMU's Python packages (pythonfmu, numpy) must be importable by the embedded
        # interpreter: this interpreter's site-packages (a virtual environment's included)
        env["PYTHONPATH"] = os.pathsep.join([*site.getsitepackages(),
                                             os.environ.get("PYTHONPATH", "")])
    if preload:
        env["LD_PRELOAD"] = str(libpython())
    args = [str(host), unzipdir, binary or md.coSimulation.modelIdentifier, md.guid, repr(STEP),
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


@pytest.fixture(scope="module")
def shim():
    if shim_binary() is None:
        pytest.skip("no shim (gcc missing): the FMUs carry pythonfmu's plain binary")


def check_rows(done: subprocess.CompletedProcess, plant) -> None:
    assert done.returncode == 0, done.stderr
    rows = np.array([[float(x) for x in line.split(",")] for line in done.stdout.split()])
    assert rows.shape == (N_STEPS, 1 + len(OUTPUTS))
    # same FMU, same inputs, same libraries; %.17g round-trips a double: identical numbers
    np.testing.assert_array_equal(rows, fmpy_reference(plant))
    assert rows[-1, 1] < rows[0, 1]  # the brake command slowed the train


def test_c_host_runs_fmu_like_fmpy(host, plant):
    check_rows(run_host(host, plant, preload=True), plant)


def test_c_host_runs_fmu_without_preload(host, plant, shim):
    """The FMU's shim loads the libpython it was built with: no LD_PRELOAD needed."""
    check_rows(run_host(host, plant, preload=False), plant)


@pytest.mark.skipif(sys.prefix != sys.base_prefix,
                    reason="a virtual environment's packages need PYTHONPATH")
def test_c_host_runs_fmu_without_preload_or_pythonpath(host, plant, shim):
    """Outside a virtual environment the embedded interpreter finds the packages itself."""
    check_rows(run_host(host, plant, preload=False, pythonpath=False), plant)


def test_c_host_exits_cleanly(host, plant, shim):
    """pythonfmu's library destructor corrupts the heap when the process exits with the library
    loaded; the shim tears pythonfmu down from an exit handler first
    (cosim/fmu/pythonfmu_shim.c)."""
    done = run_host(host, plant, preload=False, plain_exit=True)
    check_rows(done, plant)
    assert "freed" in done.stderr and "corrupted" not in done.stderr


def test_plain_pythonfmu_binary_needs_libpython_loaded_first(host, plant, shim):
    """pythonfmu's own binary (kept in the FMU as <id>_pythonfmu.so) does not load without
    libpython in the global symbol scope: why the shim exists (and why hosts of third-party
    pythonfmu FMUs need LD_PRELOAD, or to link or dlopen libpython with RTLD_GLOBAL)."""
    _, md, _ = plant
    done = run_host(host, plant, preload=False,
                    binary=md.coSimulation.modelIdentifier + SHIM_SUFFIX)
    assert done.returncode == 2
    assert "undefined symbol" in done.stderr and "Py" in done.stderr


def _fmu_ids() -> list[str]:
    from cosim.build.python import catalog

    return list(catalog())


@pytest.mark.parametrize("identifier", by_model(_fmu_ids()))
def test_c_host_runs_every_fmu_at_the_compliance_checkers_step(host, shim, built_fmus,
                                                               identifier, tmp_path):
    """The C host (no Python of its own), logging off, at the FMU Compliance Checker's step
    (stop time / 500, here twice the default step): 50 steps succeed for every FMU."""
    path = built_fmus[identifier].path
    md = read_model_description(str(path))
    unzipdir = extract(str(path), unzipdir=str(tmp_path / "fmu"))
    step = 2.0 * float(md.defaultExperiment.stepSize)
    outputs = [v.valueReference for v in md.modelVariables
               if v.causality == "output" and v.type == "Real"][:3]
    env = {k: v for k, v in os.environ.items() if k not in ("LD_PRELOAD", "PYTHONHOME")}
    env["PYTHONPATH"] = os.pathsep.join([*site.getsitepackages(),
                                         os.environ.get("PYTHONPATH", "")])
    done = subprocess.run([str(host), unzipdir, md.coSimulation.modelIdentifier, md.guid,
                           repr(step), "50", *[f"out:{vr}" for vr in outputs]],
                          capture_output=True, text=True, timeout=300, env=env)
    assert done.returncode == 0, done.stderr[-2000:]
    rows = [line.split(",") for line in done.stdout.split()]
    assert len(rows) == 50 and float(rows[-1][0]) == pytest.approx(50 * step)
