"""The native C BrakeDelayTrain FMU (cosim/fmu/native/plants/brake_delay.c behind the FMI 2 front)
against its Python core, plants.brake_delay.BrakeDelayTrain.

Tolerance: none. The C model performs the core's IEEE double operations in the core's order
(compiled -std=c99 -ffp-contract=off: no fused multiply-add, no fast math), and its one
transcendental call, exp, is the same glibc exp that Python's math.exp calls in this process,
so every output is equal bit for bit. (With another libm, e.g. the Windows build's, exp may
differ by 1 ulp per call and the trajectories by the propagation of that.)"""

from __future__ import annotations

import os
import random
import shutil
import subprocess
from pathlib import Path

import fmpy
import pytest
from fmi_state_helpers import assert_replays_from_state
from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import FMU2Slave
from native_helpers import build_unzipped, initialising, open_native, variable_rows

from cosim.build.native import CompilerMissing, _compiler, build_native
from cosim.fmu.state import to_ticks
from cosim.run.scenario import scenario_files
from plants.brake_delay import BrakeDelayTrain

ROOT = Path(__file__).resolve().parents[1]
OUTPUTS = ("v", "s", "a", "a_c", "applied_command", "grade")


@pytest.fixture(scope="module")
def native(tmp_path_factory, native_builds):
    return build_unzipped("BrakeDelayTrain", tmp_path_factory, native_builds)


def commands(seed: int, n: int) -> list[tuple[float, float]]:
    """(step size, brake command) pairs: steps of 0.2 s and irregular ones, commands held
    for a few steps, full braking to a stop included."""
    rng = random.Random(seed)
    out, u = [], 0.0
    for k in range(n):
        if k % 7 == 0:
            u = rng.choice([0.0, 30.0, 55.5, 100.0, rng.uniform(0, 100)])
        out.append((rng.choice([0.2, 0.2, 0.05, 0.37, 1.3]), u))
    return out


CASES = [
    ({}, 1),
    ({"brake_delay": 0.35, "max_step": 0.03, "v0": 12.0}, 2),
    ({"brake_time_constant": 0.9, "grade_scale": 1.5, "initial_command": 40.0}, 3),
    ({"route": "jinan_xuzhou_east", "v0": 60.0, "s0": 1000.0}, 4),
    # the unknown resistance a_d: numpy's seeded uniform draws, each held over its interval
    ({"disturbance_amplitude": 0.02, "disturbance_seed": 7, "disturbance_interval": 0.7}, 5),
    ({"disturbance_amplitude": 0.3, "disturbance_seed": 12, "v0": 8.0}, 6),
]


@pytest.mark.parametrize("params,seed", CASES)
def test_native_equals_python_core_bit_for_bit(native, params, seed):
    values = {v.name: v.start for v in BrakeDelayTrain.declarations()
              if v.causality == "parameter"}
    values.update(params)
    core = BrakeDelayTrain.from_parameters(values, ROOT)
    fmu, vr = open_native(native, params)
    out_vrs = [vr[n] for n in OUTPUTS]
    ticks, t = 0, 0.0
    stopped = False
    for h, u in commands(seed, 300):
        fmu.setReal([vr["brake_command"]], [u])
        fmu.doStep(currentCommunicationPoint=t, communicationStepSize=h)
        core.advance(to_ticks(t), to_ticks(h), {"brake_command": u})
        t = t + h
        expected = core.outputs()
        got = fmu.getReal(out_vrs)
        assert got == [expected[n] for n in OUTPUTS], (t, got, expected)
        stopped |= expected["v"] == 0.0
        ticks += 1
    fmu.terminate()
    fmu.freeInstance()
    if not params.get("route"):
        assert stopped  # the stopping logic ran


@pytest.mark.parametrize("params", [{}, {"disturbance_amplitude": 0.05,
                                         "disturbance_seed": 3}], ids=["calm", "a_d"])
def test_state_get_set_and_serialize_replay_exactly(native, params):
    fmu, vr = open_native(native, params)
    out_vrs = [vr[n] for n in OUTPUTS]
    steps = commands(7, 60)
    t = 0.0
    for h, u in steps[:30]:
        fmu.setReal([vr["brake_command"]], [u])
        fmu.doStep(t, h)
        t += h
    t_saved = t

    def rest():
        tt, rows = t_saved, []
        for h, u in steps[30:]:
            fmu.setReal([vr["brake_command"]], [u])
            fmu.doStep(tt, h)
            tt += h
            rows.append(fmu.getReal(out_vrs))
        return rows

    assert_replays_from_state(fmu, rest)
    fmu.freeInstance()


def test_errors_reach_the_log_with_logging_off(native):
    messages: list[str] = []
    fmu, vr = initialising(native, messages, "bad")
    with pytest.raises(FMICallException):
        fmu.setReal([vr["mass"]], [-5.0])
    assert any("mass = -5 outside [1, inf]" in m for m in messages), messages
    fmu.setString([vr["route"]], ["/tmp/my_route.toml"])
    with pytest.raises(FMICallException):
        fmu.exitInitializationMode()
    assert any("route = '/tmp/my_route.toml'" in m and "Python FMU" in m for m in messages)
    fmu.freeInstance()


def test_calling_sequence_is_enforced(native):
    _, md, unzipdir = native
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzipdir, instanceName="seq",
                    modelIdentifier=md.coSimulation.modelIdentifier)
    fmu.instantiate()
    with pytest.raises(FMICallException):
        fmu.doStep(0.0, 0.2)  # before initialisation
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    vr = {v.name: v.valueReference for v in md.modelVariables}
    with pytest.raises(FMICallException):
        fmu.setReal([vr["mass"]], [500e3])  # fixed after initialisation
    with pytest.raises(FMICallException):
        fmu.doStep(0.4, 0.2)  # does not continue from t = 0
    fmu.doStep(0.0, 0.2)
    fmu.terminate()
    with pytest.raises(FMICallException):
        fmu.doStep(0.2, 0.2)
    fmu.freeInstance()


def test_model_description_is_the_python_fmus(native, built_fmus):
    """Same variables, value references, units, ranges and starts as the Python FMU."""
    _, md, _ = native
    py = read_model_description(str(built_fmus["BrakeDelayTrain"].path))

    assert variable_rows(md) == variable_rows(py)
    assert md.coSimulation.modelIdentifier == "BrakeDelayTrain"
    assert md.coSimulation.canGetAndSetFMUstate and md.coSimulation.canSerializeFMUstate


def test_binary_needs_no_python(native, c_hosts):
    """The C host of tests/c_host runs the native FMU with no PYTHONPATH and no libpython:
    ldd lists no libpython, and the host's results equal fmpy's."""
    path, md, unzipdir = native
    so = Path(unzipdir) / "binaries" / "linux64" / "BrakeDelayTrain.so"
    ldd = subprocess.run(["ldd", str(so)], capture_output=True, text=True).stdout
    assert "libpython" not in ldd and "libm" in ldd
    exe = c_hosts("fmu_host")
    vr = {v.name: v.valueReference for v in md.modelVariables}
    env = {k: v for k, v in os.environ.items()
           if k not in ("PYTHONPATH", "PYTHONHOME", "LD_PRELOAD", "LD_LIBRARY_PATH")}
    done = subprocess.run(
        [str(exe), unzipdir, "BrakeDelayTrain", md.guid, "0.2", "25",
         f"in:{vr['brake_command']}=50", f"out:{vr['v']}", f"out:{vr['s']}",
         f"out:{vr['a_c']}"], capture_output=True, text=True, env=env, timeout=60)
    assert done.returncode == 0, done.stderr
    rows = [[float(x) for x in line.split(",")] for line in done.stdout.split()]
    fmu, _ = open_native(native)
    for k, row in enumerate(rows):
        fmu.setReal([vr["brake_command"]], [50.0])
        fmu.doStep(k * 0.2, 0.2)
        assert row[1:] == fmu.getReal([vr["v"], vr["s"], vr["a_c"]])
    fmu.freeInstance()


def test_missing_compiler_names_it(monkeypatch):
    monkeypatch.setenv("PATH", "/nonexistent")
    with pytest.raises(CompilerMissing, match="'gcc'"):
        _compiler("gcc")


@pytest.mark.slow
def test_windows_binary_under_wine(tmp_path):
    """binaries/win64/<id>.dll (mingw-w64) loaded and stepped under Wine by a C host built
    with mingw (tests/c_host/fmu_host_win.c). Its results equal the Linux binary's bit for bit
    where the two libms' exp agree; the bound used is 64 ulp relative (exp differs by at most
    1 ulp between correctly-rounded-to-1-ulp libms per call, 3 calls per RK4 stage set, and the
    lag and RK4 damp rather than grow that error over the 25 steps)."""
    import numpy as np

    for tool in ("x86_64-w64-mingw32-gcc", "wine"):
        if shutil.which(tool) is None:
            pytest.skip(f"{tool} not installed (apt-get install mingw-w64 wine64): "
                        "the Windows binary is not run")
    path = build_native("BrakeDelayTrain", dest=tmp_path / "fmu", windows=True)
    md = read_model_description(str(path))
    unzipdir = str(extract(str(path), unzipdir=str(tmp_path / "unzip")))
    headers = Path(fmpy.__file__).parent / "c-code"
    exe = tmp_path / "host.exe"
    subprocess.run(["x86_64-w64-mingw32-gcc", "-std=c99", "-O1", f"-I{headers}", "-o",
                    str(exe), str(ROOT / "tests" / "c_host" / "fmu_host_win.c")], check=True)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    env = dict(os.environ, WINEDEBUG="-all")
    done = subprocess.run(
        ["wine", str(exe), "Z:" + unzipdir.replace("/", "\\"), "BrakeDelayTrain", md.guid,
         "0.2", "25", f"in:{vr['brake_command']}=50", f"out:{vr['v']}", f"out:{vr['s']}",
         f"out:{vr['a_c']}"], capture_output=True, text=True, env=env, timeout=600)
    assert done.returncode == 0, done.stderr
    rows = np.array([[float(x) for x in line.split(",")] for line in done.stdout.split()])
    assert rows.shape == (25, 4)
    fmu, _ = open_native((path, md, unzipdir))
    linux = []
    for k in range(25):
        fmu.setReal([vr["brake_command"]], [50.0])
        fmu.doStep(k * 0.2, 0.2)
        linux.append(fmu.getReal([vr["v"], vr["s"], vr["a_c"]]))
    fmu.freeInstance()
    np.testing.assert_allclose(rows[:, 1:], np.array(linux), rtol=64 * np.finfo(float).eps,
                               atol=0.0)


SEED000 = [n for n in scenario_files() if n.startswith("seed000_")]
TIMING_KEYS = ("wall_time", "real_time_factor", "fmu_wall", "solve_time")  # clock readings


def _timing(key: str) -> bool:
    return any(t in key for t in TIMING_KEYS)


@pytest.mark.parametrize("scenario", SEED000)
def test_closed_loops_with_the_native_plant_are_the_same(native, scenario):
    """Every shipped seed-000 scenario with the native plant in place of the Python FMU: the
    recorded series and the summary are equal (the plant is equal bit for bit, so the loop
    is); only the wall-clock figures differ."""
    from cosim.run.simulate import run_scenario

    python = run_scenario(scenario, plot=False)
    c = run_scenario(scenario, overrides={"plant.fmu": str(native[0])}, plot=False)
    assert c.frame.equals(python.frame)
    assert ({k: v for k, v in c.summary.items() if not _timing(k)}
            == {k: v for k, v in python.summary.items() if not _timing(k)})


