"""Built FMUs: fmpy validation, many FMUs in one process, closed-loop state save/restore
through FMI, and an FMU run in a fresh virtual environment without this package."""

from __future__ import annotations

import os
import subprocess
import textwrap
import venv
from pathlib import Path

import pytest
from fmi_state_helpers import rerun_after_restore
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave
from fmpy.validation import validate_fmu


def test_every_fmu_validates(built_fmus):
    assert built_fmus, "the catalog is empty"
    for spec in built_fmus.values():
        assert validate_fmu(str(spec.path)) == [], spec.identifier


class Instance:
    def __init__(self, path: Path, name: str) -> None:
        self.md = read_model_description(str(path))
        self.dir = extract(str(path))
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        self.fmu = FMU2Slave(guid=self.md.guid, unzipDirectory=self.dir, instanceName=name,
                             modelIdentifier=self.md.coSimulation.modelIdentifier)
        self.fmu.instantiate()
        self.fmu.setupExperiment(startTime=0.0)
        self.fmu.enterInitializationMode()
        self.fmu.exitInitializationMode()

    def get(self, name: str) -> float:
        return self.fmu.getReal([self.vr[name]])[0]

    def set(self, name: str, value: float) -> None:
        self.fmu.setReal([self.vr[name]], [value])


def test_all_fmus_and_two_instances_each_in_one_process(built_fmus):
    """Every FMU twice at once: instantiate, initialise, step; instances stay independent."""
    instances = {}
    for spec in built_fmus.values():
        for k in (1, 2):
            instances[(spec.identifier, k)] = Instance(spec.path, f"{spec.identifier}_{k}")
    for (_, k), inst in instances.items():
        reals = [v for v in inst.md.modelVariables
                 if v.causality == "input" and v.type == "Real"]
        for v in reals:  # different inputs in the two instances
            lo = float(v.min) if v.min is not None else 0.0
            hi = float(v.max) if v.max is not None else lo + 10.0
            inst.set(v.name, lo + (hi - lo) * (0.2 if k == 1 else 0.6))
        for step in range(10):
            inst.fmu.doStep(currentCommunicationPoint=0.2 * step, communicationStepSize=0.2)
    plant1, plant2 = instances[("BrakeDelayTrain", 1)], instances[("BrakeDelayTrain", 2)]
    assert plant1.get("a_c") != plant2.get("a_c")
    for inst in instances.values():
        inst.fmu.terminate()
        inst.fmu.freeInstance()


def test_closed_loop_state_save_restore_reproduces_rest(built_fmus):
    """Get + serialize the whole state of plant and PID mid-run, finish the run, restore from
    the bytes, rerun: identical trajectories (dead-time history, lag, integrator, schedule)."""
    plant = Instance(built_fmus["BrakeDelayTrain"].path, "plant")
    pid = Instance(built_fmus["StopPid"].path, "pid")
    h = 0.2

    def step(k: int) -> tuple[float, float, float]:
        pid.set("v", plant.get("v"))
        pid.set("s", plant.get("s"))
        u = pid.get("brake_command")
        plant.set("brake_command", u)
        plant.fmu.doStep(currentCommunicationPoint=k * h, communicationStepSize=h)
        pid.fmu.doStep(currentCommunicationPoint=k * h, communicationStepSize=h)
        return plant.get("v"), plant.get("s"), u

    first, second = rerun_after_restore([plant, pid], step, 60, 200)
    assert first == second
    assert first[-1][0] == 0.0  # the run got to the stop


@pytest.mark.slow
def test_fmu_runs_in_fresh_venv_without_this_package(built_fmus, tmp_path):
    """The FMU bundles our code: a venv with only numpy/scipy/osqp (and fmpy as host) runs it."""
    env_dir = tmp_path / "venv"
    venv.EnvBuilder(with_pip=True).create(env_dir)
    py = env_dir / "bin" / "python"
    subprocess.run([str(py), "-m", "pip", "install", "-q", "numpy", "scipy", "osqp", "fmpy"],
                   check=True, timeout=600)
    script = textwrap.dedent(f"""
        import importlib.util, sys
        for name in ("cosim", "plants", "controllers", "pythonfmu"):
            assert importlib.util.find_spec(name) is None, name + " must not be importable"
        from fmpy import simulate_fmu
        r = simulate_fmu({str(built_fmus["BrakeDelayTrain"].path)!r}, stop_time=3.0,
                         output_interval=0.5, start_values={{"brake_command": 50.0}})
        print(r["v"][-1], r["a_c"][-1])
        r = simulate_fmu({str(built_fmus["StopPid"].path)!r}, stop_time=1.0,
                         output_interval=0.2, start_values={{"v": 20.0, "s": 0.0}})
        print(r["brake_command"][-1])
    """)
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME")}
    done = subprocess.run([str(py), "-c", script], cwd=tmp_path, env=env, capture_output=True,
                          text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    v_end, a_c_end, command = map(float, done.stdout.split())
    assert 0 < v_end < 20.0 and a_c_end < -0.4
    assert command == pytest.approx(0.5 / 0.0107, rel=1e-6)  # feedforward at v = v_ref


def test_further_instances_reuse_the_bundled_modules(built_fmus):
    """The bundle is imported once per process and digest (two extractions, three instances):
    the modules are the same objects, the states stay separate."""
    import re
    import sys
    import zipfile

    spec = built_fmus["BrakeDelayTrain"]
    with zipfile.ZipFile(spec.path) as z:
        name = next(n for n in z.namelist()
                    if re.fullmatch(r"resources/atocosim_[a-z0-9_]+\.py", n))
        entry = z.read(name).decode()
    digest = re.search(r'_DIGEST = "([0-9a-f]{64})"', entry).group(1)
    insts = [Instance(spec.path, f"shared_{k}") for k in range(3)]
    try:
        registry = sys.modules["atocosim_bundle_registry"].loaded
        keys = [key for key in registry if key[0] == digest]
        assert keys == [(digest, spec.module)]
        insts[0].set("brake_command", 80.0)
        for inst in insts:  # 3 s: past the brake dead time (1 s) and into the lag
            for step in range(15):
                inst.fmu.doStep(currentCommunicationPoint=0.2 * step, communicationStepSize=0.2)
        assert insts[0].get("v") < insts[1].get("v") == insts[2].get("v")
    finally:
        for inst in insts:
            inst.fmu.terminate()
            inst.fmu.freeInstance()
