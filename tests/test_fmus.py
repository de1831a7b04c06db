"""Built FMUs (fmpy validation of each: tests/compliance/test_compliance.py, check
``fmpy-validation``; many FMUs in one process: its check ``together``): two instances of one
FMU with other inputs, closed-loop state save/restore through FMI, an FMU run in a fresh
virtual environment without this package, and one value check per FMU derived independently
of its code (analytic law, invariant or scipy)."""

from __future__ import annotations

import math
import os
import subprocess
import textwrap
import venv
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from fmi_state_helpers import rerun_after_restore
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave
from matrix import by_model


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


def test_two_instances_of_one_fmu_with_other_inputs_give_other_outputs(built_fmus):
    """Two BrakeDelayTrain instances at once in this process, given other inputs: instantiate,
    initialise, step; their outputs differ (the instances stay independent). Every catalog
    FMU twice in one process, each instance interleaved with all the others giving what it
    gives alone: tests/compliance/test_compliance.py::test_all_fmus_together_in_one_process
    (check_together)."""
    spec = built_fmus["BrakeDelayTrain"]
    instances = {(spec.identifier, k): Instance(spec.path, f"{spec.identifier}_{k}")
                 for k in (1, 2)}
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


# -- one value check per FMU, each derived independently of the FMU's code -------------------
# (an analytic law computed here by hand, an invariant, or an independent solver); a new FMU
# must add its check: test_every_fmu_has_a_value_check.

ROUTES = Path(__file__).resolve().parent.parent / "plants" / "routes"
VALUE_CHECKS: dict[str, Any] = {}


def _checks(*identifiers: str):
    def register(fn):
        for identifier in identifiers:
            VALUE_CHECKS[identifier] = fn
        return fn
    return register


class _Fmu:
    """An fmpy instance with parameters set by their declared type, started at ``start``."""

    def __init__(self, path: Path, start: float = 0.0, **params: Any) -> None:
        self.md = read_model_description(str(path))
        self.vars = {v.name: v for v in self.md.modelVariables}
        self.fmu = FMU2Slave(guid=self.md.guid, unzipDirectory=extract(str(path)),
                             instanceName="checked",
                             modelIdentifier=self.md.coSimulation.modelIdentifier)
        self.fmu.instantiate()
        self.fmu.setupExperiment(startTime=start)
        self.fmu.enterInitializationMode()
        for name, value in params.items():
            self.set(name, value)
        self.fmu.exitInitializationMode()
        self.t = start

    def set(self, name: str, value: Any) -> None:
        var = self.vars[name]
        setter = {"Real": self.fmu.setReal, "Integer": self.fmu.setInteger,
                  "Boolean": self.fmu.setBoolean, "String": self.fmu.setString}[var.type]
        setter([var.valueReference], [value])

    def get(self, name: str) -> float:
        var = self.vars[name]
        getter = {"Real": self.fmu.getReal, "Integer": self.fmu.getInteger}[var.type]
        return getter([var.valueReference])[0]

    def start(self, name: str) -> float:
        return float(self.vars[name].start)

    def step(self, h: float, n: int = 1) -> None:
        for _ in range(n):
            self.fmu.doStep(currentCommunicationPoint=self.t, communicationStepSize=h)
            self.t += h

    def close(self) -> None:
        self.fmu.terminate()
        self.fmu.freeInstance()


def _distance_reference(csv: Path, x: float) -> float:
    """Speed (m/s) of a speed-distance profile at ``x``, constant acceleration between its
    points (v^2 linear in position), read from the CSV (position_m, speed_kmh) here."""
    pos, kmh = np.loadtxt(csv, delimiter=",", comments="#", skiprows=3, unpack=True)
    i = int(np.searchsorted(pos, x, side="right")) - 1
    v0, v1 = kmh[i] / 3.6, kmh[i + 1] / 3.6
    accel = (v1**2 - v0**2) / (2.0 * (pos[i + 1] - pos[i]))
    return math.sqrt(v0**2 + 2.0 * accel * (x - pos[i]))


# v_ref: O(100 m/s) from a handful of roundings of v^2 = O(1e4 m2/s2): well under 1e-9 m/s
V_REF_TOL = 1e-9


@_checks("BrakeDelayTrain")
def _coasting_on_level_track(path: Path) -> None:
    """No brake, grades scaled to 0: m dv/dt = -(a + b v + c v^2), ds/dt = v, solved by scipy
    (rtol 1e-12). The FMU's RK4 at h = 0.01 s on a resistance changing over m v / R ~ 800 s
    errs by ~(h / 800 s)^4 relative: 1e-9 m/s and 1e-7 m after 60 s are far above that."""
    from scipy.integrate import solve_ivp

    fmu = _Fmu(path, grade_scale=0.0, v0=20.0)
    try:
        fmu.step(0.2, 300)
        m, a, b, c = (fmu.start(n) for n in ("mass", "davis_a", "davis_b", "davis_c"))
        sol = solve_ivp(lambda t, y: [-(a + b * y[0] + c * y[0] ** 2) / m, y[0]], (0.0, 60.0),
                        [20.0, 0.0], rtol=1e-12, atol=1e-12, method="DOP853")
        v, s = sol.y[:, -1]
        assert abs(fmu.get("v") - v) < 1e-9 and abs(fmu.get("s") - s) < 1e-7
        assert 18.0 < v < 19.0  # it did coast: 1.7 m/s lost to resistance
        assert fmu.get("a_c") == 0.0 and fmu.get("applied_command") == 0.0
    finally:
        fmu.close()


@_checks("Emu3", "Emu8")
def _emu_coasting_on_level_track(path: Path) -> None:
    """Zero force on level track from 80 m/s: the mass-weighted mean speed obeys
    M dv/dt = -sum_i R_i(v_i) (couplers are internal), solved by scipy with every unit at the
    mean speed. That lumping errs by at most sum_i (b_i + c_i (|v_i| + |v|)) |v_i - v| / M per
    second, bounded here from the unit speeds the FMU reports; the FMU's second-order
    (exponential midpoint) integrator adds about (h^2 / 12) T |f' f| (f = dv/dt at 80 m/s,
    h = max_step): allowed with a factor 12 (measured 4.5e-9 m/s for Emu8)."""
    from scipy.integrate import solve_ivp

    from plants.emu import DEFAULT_CONFIGURATION, emu_config

    units = sum(1 for n in read_model_description(str(path)).modelVariables
                if n.name.startswith("force["))
    p = emu_config(DEFAULT_CONFIGURATION[units])
    m = np.array(p.masses)
    a, b, c = (np.array(x) for x in (p.davis_a, p.davis_b, p.davis_c))
    fmu = _Fmu(path, route="seed004_level", v0=80.0)
    try:
        bound, h = 0.0, 0.2
        for _ in range(300):
            fmu.step(h)
            vi = np.array([fmu.get(f"v[{i}]") for i in range(1, units + 1)])
            vm = fmu.get("v")
            bound += h * float(np.sum((b + c * (np.abs(vi) + abs(vm))) * np.abs(vi - vm)))
        sol = solve_ivp(lambda t, y: [-np.sum(a + b * y[0] + c * y[0] ** 2) / m.sum()],
                        (0.0, 60.0), [80.0], rtol=1e-12, atol=1e-12, method="DOP853")
        f = np.sum(a + b * 80.0 + c * 80.0**2) / m.sum()
        df = np.sum(b + 2.0 * c * 80.0) / m.sum()
        integrator = fmu.start("max_step") ** 2 * 60.0 * f * df
        assert abs(fmu.get("v") - sol.y[0, -1]) <= bound / m.sum() + integrator
        assert 70.0 < sol.y[0, -1] < 78.0  # it did coast
        assert fmu.get("power") == 0.0
    finally:
        fmu.close()


@_checks("FreightTrain")
def _freight_at_rest_stays_at_rest(path: Path, tmp_path: Path) -> None:
    """At rest on a level route with no force and the brakes released, nothing moves: every
    vehicle stays where it was for 60 s (static resistance holds it), and the tail is one
    train length behind the head."""
    route = tmp_path / "level.toml"
    route.write_text('name = "level"\nlength_m = 5000.0\ngrade = [[0.0, 0.0]]\n')
    fmu = _Fmu(path, route=str(route), v0=0.0, s0=1000.0)
    try:
        tail = fmu.get("s_tail")
        fmu.step(0.5, 120)
        assert (fmu.get("s"), fmu.get("s_tail")) == (1000.0, tail)
        # speeds at rounding level of the coupler solve (u |F| h / m ~ 1e-16 1e6 0.5 / 1e5)
        assert abs(fmu.get("v")) < 1e-15 and abs(fmu.get("v_tail")) < 1e-15
        length = fmu.start("loco_length") + 108 * fmu.start("wagon_length")
        assert 1000.0 - tail == pytest.approx(length, rel=1e-12)
    finally:
        fmu.close()


@_checks("StopPid")
def _pid_first_output(path: Path) -> None:
    """Eq. (sec. 4.1): u = a0/c + kp e + ki e T (no derivative at the first sample), with
    v_ref(0) = sqrt(2 a0 s_stop) = 20 m/s and e = 0.05 m/s."""
    fmu = _Fmu(path)
    try:
        fmu.set("v", 20.05)
        fmu.set("s", 0.0)
        e = 20.05 - math.sqrt(2 * 0.5 * 400.0)
        expected = 0.5 / 0.0107 + 60.0 * e + 10.0 * e * 0.2
        assert fmu.get("brake_command") == pytest.approx(expected, rel=1e-14)
        assert fmu.get("v_ref") == 20.0
    finally:
        fmu.close()


@_checks("StopMpc", "StopRmpc", "StopRsmpc")
def _mpc_holds_at_the_stop_point(path: Path) -> None:
    """At rest at the stop point the predictive controllers hold the train (standstill rule):
    the command is max(previous = 0, standstill_command), the reference speed 0."""
    fmu = _Fmu(path)
    try:
        fmu.set("v", 0.0)
        fmu.set("s", fmu.start("stop_point"))
        assert fmu.get("brake_command") == max(0.0, fmu.start("standstill_command")) > 0.0
        assert fmu.get("v_ref") == 0.0
    finally:
        fmu.close()


def _set_emu_inputs(fmu: _Fmu, v: list[float], s: float, limit: float = 3e5) -> None:
    for name in fmu.vars:
        if name.startswith(("traction_limit[", "brake_limit[")):
            fmu.set(name, limit)
    if "v[1]" in fmu.vars:
        for i, vi in enumerate(v, 1):
            fmu.set(f"v[{i}]", vi)
    else:
        fmu.set("v", float(np.mean(v)))
    fmu.set("s", s)


@_checks("EmuSpeedPid3", "EmuSpeedPid8", "EmuMfac3", "EmuIsmc3", "EmuIsmpc3", "EmuGpc3")
def _emu_controller_reference_and_total(path: Path) -> None:
    """v_ref at the measured head position is the bundled speed-distance profile there
    (computed here from the CSV); speed_error = mean speed - v_ref; force_demand is the sum
    of the unit forces, each within the limits the plant gave."""
    fmu = _Fmu(path)
    try:
        units = sum(1 for n in fmu.vars if n.startswith("force["))
        v = [30.0 + 0.1 * i for i in range(units)]
        _set_emu_inputs(fmu, v, 1234.5)
        v_ref = _distance_reference(ROUTES / "jinan_xuzhou_east_reference.csv", 1234.5)
        assert abs(fmu.get("v_ref") - v_ref) < V_REF_TOL
        assert fmu.get("speed_error") == pytest.approx(np.mean(v) - fmu.get("v_ref"),
                                                       abs=1e-12)
        forces = [fmu.get(f"force[{i}]") for i in range(1, units + 1)]
        assert fmu.get("force_demand") == pytest.approx(sum(forces), rel=1e-12, abs=1e-6)
        assert all(-3e5 <= f <= 3e5 for f in forces)
    finally:
        fmu.close()


@_checks("Gmpc3", "MbMpc3", "Empc3")
def _hybrid_mpc_reference_at_100_s(path: Path) -> None:
    """Started at t = 100 s on the seed 004 speed-time reference (0 -> 30 m/s over 75 s, then
    30 m/s): v_ref = 30 m/s and s_ref = 30 * 75 / 2 + 30 * 25 = 1875 m by hand; the trailer
    (car 2 of crh3_3car) gives no force; the total is the sum of the car forces."""
    fmu = _Fmu(path, start=100.0)
    try:
        _set_emu_inputs(fmu, [30.0, 30.0, 30.0], 1875.0)
        assert fmu.get("v_ref") == 30.0
        assert fmu.get("s_ref") == pytest.approx(1875.0, rel=1e-12)
        forces = [fmu.get(f"force[{i}]") for i in (1, 2, 3)]
        assert forces[1] == 0.0
        assert fmu.get("force_demand") == pytest.approx(sum(forces), rel=1e-12, abs=1e-6)
    finally:
        fmu.close()


@_checks("FreightPid", "FreightFpid", "FreightPreview", "FreightSmc")
def _freight_controller_reference_and_final_hold(path: Path) -> None:
    """v_ref at the measured position is the route's speed-distance profile (computed here
    from the CSV); at rest at the end of the profile the train is held by the pipe reduction
    hold_reduction with no locomotive force (the shared final-stop rule)."""
    csv = ROUTES / "freight_20km_reference.csv"
    fmu = _Fmu(path)
    try:
        fmu.set("v", 10.0)
        fmu.set("s", 1234.5)
        assert abs(fmu.get("v_ref") - _distance_reference(csv, 1234.5)) < V_REF_TOL
        assert fmu.get("speed_error") == 10.0 - fmu.get("v_ref")
    finally:
        fmu.close()
    end = float(np.loadtxt(csv, delimiter=",", comments="#", skiprows=3)[-1, 0])
    fmu = _Fmu(path)
    try:
        fmu.set("v", 0.0)
        fmu.set("s", end)
        assert fmu.get("v_ref") == 0.0
        assert fmu.get("pipe_reduction") == fmu.start("hold_reduction") > 0.0
        assert fmu.get("force_demand") == 0.0
    finally:
        fmu.close()


@_checks("Crh3Train")
def _crh3_coasting_on_level_track(path: Path) -> None:
    """No force on the level first 20 km of the seed 003 route from 80 m/s: M (1 + gamma)
    dv/dt = -(a + b v + c v^2) (eq. 1 with the Davis form of w0), solved by scipy (rtol 1e-12).
    The FMU's RK4 at h <= 0.2 s on a resistance changing over v / |dv/dt| ~ 1000 s errs by
    ~(h / 1000 s)^4 relative per step: 1e-9 m/s and 1e-7 m after 60 s are far above that.
    Energy (eq. 9): no traction, no regeneration, auxiliary e0 t exactly."""
    from scipy.integrate import solve_ivp

    fmu = _Fmu(path, v0=80.0, s0=1000.0)
    try:
        fmu.step(0.2, 300)
        m = fmu.start("mass") * (1.0 + fmu.start("rotating_mass_factor"))
        a, b, c = (fmu.start(n) for n in ("davis_a", "davis_b", "davis_c"))
        sol = solve_ivp(lambda t, y: [-(a + b * y[0] + c * y[0] ** 2) / m, y[0]], (0.0, 60.0),
                        [80.0, 1000.0], rtol=1e-12, atol=1e-12, method="DOP853")
        v, s = sol.y[:, -1]
        assert abs(fmu.get("v") - v) < 1e-9 and abs(fmu.get("s") - s) < 1e-7
        assert 70.0 < v < 78.0  # it did coast (6.3 m/s lost to resistance)
        assert fmu.get("energy_traction") == 0.0 and fmu.get("energy_regen") == 0.0
        assert fmu.get("energy_aux") == pytest.approx(fmu.start("aux_power") * 60.0, rel=1e-12)
    finally:
        fmu.close()


@_checks("Crh3Gpc", "Crh3LmiMpc")
def _crh3_tracker_first_event(path: Path) -> None:
    """At rest at the origin at t = 0 both seed 003 trackers start the profile's accelerating
    phase: phase 1, a traction demand within the plant's limit and the comfort limit, force =
    M (1 + gamma) u (the interface's definition), speed_error = v - v_ref."""
    fmu = _Fmu(path)
    try:
        fmu.set("v", 0.0)
        fmu.set("s", 0.0)
        fmu.set("traction_limit", 6.0e5)
        fmu.set("brake_limit", 6.0e5)
        u = fmu.get("accel_demand")
        m = fmu.start("mass") * (1.0 + fmu.start("rotating_mass_factor"))
        assert fmu.get("phase") == 1.0
        assert 0.0 < u <= fmu.start("accel_max")
        assert fmu.get("force") == pytest.approx(m * u, rel=1e-12)
        assert fmu.get("force") <= 6.0e5
        assert fmu.get("speed_error") == pytest.approx(-fmu.get("v_ref"), abs=1e-12)
    finally:
        fmu.close()


def test_every_fmu_has_a_value_check(built_fmus):
    assert built_fmus, "the catalog is empty"
    assert set(built_fmus) == set(VALUE_CHECKS)


@pytest.mark.parametrize("identifier", sorted(VALUE_CHECKS))
def test_fmu_value(built_fmus, identifier, tmp_path):
    check = VALUE_CHECKS[identifier]
    args = (built_fmus[identifier].path, tmp_path)
    check(*args[:check.__code__.co_argcount])



def test_a_truncated_fmu_is_stale_and_not_listed_as_built(built_fmus, tmp_path, monkeypatch):
    """A truncated or garbled archive newer than its sources is rebuilt (zip CRCs checked, not
    only the mtime) and ``cosim list`` does not call it built."""
    import os
    import shutil
    import subprocess
    import sys

    from cosim.build import python as build

    good = built_fmus["StopPid"].path
    monkeypatch.setattr(build, "FMU_DIR", tmp_path)
    spec = build.catalog()["StopPid"]
    assert spec.path == tmp_path / "StopPid.fmu"
    shutil.copy2(good, spec.path)
    assert build.is_intact(spec.path) and not build.is_stale(spec)
    data = good.read_bytes()
    for broken in (data[: len(data) // 2], data[:-300] + bytes(300),
                   data[:4000] + bytes(64) + data[4064:]):
        spec.path.write_bytes(broken)
        os.utime(spec.path, None)  # newer than every source file
        assert not build.is_intact(spec.path)
        assert build.is_stale(spec)
    done = subprocess.run(
        [sys.executable, "-c", "import sys; from cosim.build import python as build; "
         f"build.FMU_DIR = __import__('pathlib').Path({str(tmp_path)!r}); "
         "from cosim import cli; sys.argv = ['cosim', 'list']; cli.main()"],
        capture_output=True, text=True, timeout=120)
    row = next(line for line in done.stdout.splitlines() if line.split()[:1] == ["StopPid"])
    assert "corrupt" in row and "yes" not in row.split("│")[1], done.stdout


def _fmu_ids() -> list[str]:
    from cosim.build.python import catalog

    return list(catalog())


@pytest.mark.parametrize("identifier", by_model(_fmu_ids()))
def test_every_fmu_runs_in_fmpy_at_the_compliance_checkers_step(built_fmus, identifier):
    """fmpy.simulate_fmu with its defaults but the stop time, at the FMU Compliance Checker's
    step (stop time / 500), here twice the FMU's default step: a controller executes the
    events inside each step with the inputs held (no refusal, no error)."""
    from fmpy import read_model_description, simulate_fmu

    path = str(built_fmus[identifier].path)
    step = 2.0 * float(read_model_description(path).defaultExperiment.stepSize)
    result = simulate_fmu(path, stop_time=500 * step, output_interval=step)
    assert len(result) == 501
    assert result["time"][-1] == pytest.approx(500 * step)


@pytest.mark.parametrize("identifier", by_model(_fmu_ids()))
def test_every_fmu_runs_in_fmpy_with_default_arguments(built_fmus, identifier):
    """``fmpy.simulate_fmu(path)``: the FMU's default experiment, fmpy's default step."""
    from fmpy import simulate_fmu

    result = simulate_fmu(str(built_fmus[identifier].path))
    assert len(result) > 1
