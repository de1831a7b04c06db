"""The native C controller FMUs (cosim/fmu/native/runtime/controller_backend.c over a law file)
against the Python FMU wrappers of their cores (cosim/fmu/slave.py's SampledControllerSlave over
controllers/...), driven through the same FMI calls, and the shipped closed loops with native
controllers against the same loops with Python ones.

Tolerance: none for the PIDs. Their laws are scalar IEEE double arithmetic (+, -, *, /, sqrt,
comparisons) which the C twins perform in the cores' order, compiled -std=c99
-ffp-contract=off (no fused multiply-add, no fast math); sqrt is correctly rounded by IEEE 754
and numpy.interp's arithmetic (slope times offset plus value, no FMA in numpy's baseline
build) is written out the same way, so every output equals the Python one bit for bit, and so
do the closed loops. The timing contract (events on read, held inputs in long steps,
strict_steps, next_event_time) is integer-nanosecond logic and is compared exactly too.

The explicit MPC (Empc3) has the same scalar operations, the same region data and the same
point-location tree, but four dot products (the mean speed c'v, n = 3; the reference slope's
numerator and denominator, n = N; E theta and F theta, n = 8, plus the offset) that numpy
hands to BLAS, which may sum in another order and with fused multiply-adds (it depends on the
CPU); the C twin sums in index order. Two summations of n products differ by at most
2 gamma_n sum |x_i y_i| (gamma_n = n u / (1 - n u), u = 2^-53), so a force differs by at most
dF = 1e3 (2 gamma_9 max(|F| |theta|_max + |f|) + |F_e| d_e + |F_slope| d_slope) N, the
maxima over every region of the data and theta over its parameter box, d_e and d_slope the
bounds of the two dot-product parameters (:func:`empc_force_bound`). Discrete outputs (mode,
region, counters) are compared exactly: a different region would need theta within that
bound of a region's face. In closed loop the per-event differences add up: over n_events
events the summaries may differ by n_events dF relative to the run's mean force (each
perturbation counted as if the loop never damped it).
"""

from __future__ import annotations

import fnmatch
import functools
import math
import random
import re
import shutil
import tempfile
import zlib

import numpy as np
import pytest
from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import FMU2Slave

from controllers.hybrid.explicit import PARAM_NAMES, ExplicitLaw
from controllers.hybrid.explicit_mpc import regions_path
from cosim.build.native import native_path
from cosim.build.python import catalog
from cosim.run.scenario import ScenarioError, load_scenario
from cosim.run.simulate import run_scenario
from plants.emu import emu_config

CONTROLLERS = ("StopPid", "EmuSpeedPid3", "EmuSpeedPid8", "Empc3")
UNIT = 2.0**-53


def gamma(n: int) -> float:
    return n * UNIT / (1 - n * UNIT)


@functools.cache
def empc_force_bound(regions: str = "seed004_empc_crh3_3car") -> float:
    """dF (N): the largest difference of one car's force between two summation orders of the
    EMPC's dot products, over every region and theta in its box (module docstring)."""
    law = ExplicitLaw.load(regions_path(regions))
    horizon, ts = int(float(law.meta["N"])), float(law.meta["sample_time"])
    steps = np.arange(1, horizon + 1) * ts
    worst = 0.0
    for key, rs in law.sets.items():
        box = law.boxes[key]
        theta_max = np.abs(box).max(axis=1)
        # |vm| <= v_ref + e at most, unless theta[e] is clipped (then its difference is 0)
        v_max = box[PARAM_NAMES.index("v_ref"), 1] + box[PARAM_NAMES.index("e"), 1]
        d_e = 2 * gamma(3) * v_max + 2 * UNIT * theta_max[0]
        num = float(steps.sum()) * v_max  # sum s_k |v_ref(t + s_k) - v_ref(t)|
        den = float(steps @ steps)
        d_slope = (2 * gamma(horizon) * (num + num) / den + 2 * UNIT
                   * theta_max[PARAM_NAMES.index("a_ref")])
        terms = np.abs(rs.F) @ theta_max + np.abs(rs.f)
        du = (2 * gamma(9) * terms + np.abs(rs.F[:, :, 0]) * d_e
              + np.abs(rs.F[:, :, PARAM_NAMES.index("a_ref")]) * d_slope)
        worst = max(worst, float(du.max()))
    return 1e3 * worst * (1 + 2 * UNIT)


@pytest.fixture(scope="module")
def natives(tmp_path_factory, native_builds):
    out = {}
    for ident in CONTROLLERS:
        path = native_builds(ident)[2]
        md = read_model_description(str(path), validate=True)
        out[ident] = (md, extract(str(path), unzipdir=str(tmp_path_factory.mktemp(ident))))
    return out


class Pair:
    """One native and one Python instance of a controller, given the same FMI calls."""

    def __init__(self, natives, ident: str, params: dict) -> None:
        md, unzipdir = natives[ident]
        self.md = md
        self.vars = {v.name: v for v in md.modelVariables}
        self.outputs = [v for v in md.modelVariables if v.causality == "output"]
        self.inputs = [v for v in md.modelVariables if v.causality == "input"]
        self.v_seen = 0.0  # largest |unit speed| set so far (m/s)
        self.native = FMU2Slave(guid=md.guid, unzipDirectory=unzipdir, instanceName="native",
                                modelIdentifier=md.coSimulation.modelIdentifier)
        self.native.instantiate()
        self.py = catalog()[ident].load()(instance_name="python",
                                          resources=tempfile.mkdtemp())
        self.native.setupExperiment(startTime=0.0)
        self.py.setup_experiment(0.0)
        self.native.enterInitializationMode()
        self.py.enter_initialization_mode()
        for name, value in params.items():
            self.set(name, value)
        self.native.exitInitializationMode()
        self.py.exit_initialization_mode()

    def set(self, name: str, value) -> None:
        var = self.vars[name]
        vr = [var.valueReference]
        kind = {"Real": "real", "Integer": "integer", "Boolean": "boolean",
                "String": "string"}[var.type]
        getattr(self.native, f"set{kind.capitalize()}")(vr, [value])
        getattr(self.py, f"set_{kind}")(vr, [value])

    def set_inputs(self, values: list[float]) -> None:
        vrs = [v.valueReference for v in self.inputs]
        self.v_seen = max([self.v_seen] + [
            abs(x) for v, x in zip(self.inputs, values, strict=True) if v.name.startswith("v[")])
        self.native.setReal(vrs, values)
        self.py.set_real(vrs, values)

    def read(self) -> tuple[list, list]:
        native, py = [], []
        for v in self.outputs:
            vr = [v.valueReference]
            if v.type == "Real":
                native.append(self.native.getReal(vr)[0])
                py.append(self.py.get_real(vr)[0])
            else:
                native.append(self.native.getInteger(vr)[0])
                py.append(self.py.get_integer(vr)[0])
        return native, py

    def step(self, t: float, h: float) -> None:
        self.native.doStep(t, h)
        self.py.do_step(t, h)


def random_inputs(rng: random.Random, ident: str, names: list[str]) -> list[float]:
    """Measured values over the shipped scenarios' ranges: speeds 0..90 m/s (some at rest;
    the cars of a train within millimetres per second of each other, or a few cm/s),
    positions over the stopping curve or the whole line, coupler forces of +-40 kN, envelopes
    >= 0 with zeros and negative readings (clamped by the law)."""
    out = []
    train = rng.uniform(0.0, 90.0)
    spread = rng.choice([1e-4, 1e-3, 3e-2])
    for name in names:
        if name.startswith("v["):
            out.append(train + rng.uniform(-spread, spread))
        elif name.startswith("coupler_force"):
            out.append(rng.uniform(-4e4, 4e4))
        elif name == "v":
            out.append(0.0 if rng.random() < 0.05 else rng.uniform(0.0, 90.0))
        elif name == "s":
            out.append(rng.uniform(0.0, 430.0) if ident == "StopPid"
                       else rng.uniform(-10.0, 280000.0))
        else:  # traction_limit[i], brake_limit[i]
            out.append(rng.choice([0.0, -5.0, rng.uniform(0, 3e5), rng.uniform(0, 3e5)]))
    return out


CASES = [
    ("StopPid", {}),
    ("StopPid", {"hold_at_stop_point": False, "kd": 5.0, "kp": 40.0, "u_min": -10.0}),
    ("StopPid", {"feedforward": False, "sample_time": 0.25}),
    # the known resistance fed forward: Davis / mass + the bundled route's grade
    ("StopPid", {"resistance_feedforward": True}),
    ("StopPid", {"resistance_feedforward": True, "route": "jinan_xuzhou_east",
                 "stop_point": 30000.0, "davis_b": 120.0}),
    ("EmuSpeedPid3", {}),
    ("EmuSpeedPid3", {"kd": 0.2, "derivative_filter": 0.5, "rate_limit": 0.4}),
    ("EmuSpeedPid8", {"reference": "seed004_crh3_reference", "sample_time": 1.0,
                      "feedforward": False, "kd": 0.1}),
    ("Empc3", {}),
    ("Empc3", {"brake_from": 20.0, "brake_until_speed": 45.0}),
]


def assert_outputs_agree(pair: Pair, ident: str, native: list, py: list, where: str) -> None:
    """Equal, except the EMPC's forces (within :func:`empc_force_bound`) and its speed error
    (the mean speed's dot product: 2 gamma_3 sum |c_i v_i| <= 2 gamma_3 max v, the max over
    every speed set so far: an event computes from the inputs in effect at its own time, which
    may be an earlier step's)."""
    if ident != "Empc3":
        assert native == py, where
        return
    d_force = empc_force_bound()
    v_max = max([pair.v_seen] + [abs(pair.py.values[v.name]) for v in pair.inputs
                                 if v.name.startswith("v[")])
    for var, a, b in zip(pair.outputs, native, py):
        if var.name.startswith("force["):
            tol = d_force
        elif var.name == "force_demand":
            tol = 3 * d_force + 2 * gamma(3) * 3 * abs(b)
        elif var.name == "speed_error":
            tol = 2 * gamma(3) * abs(v_max) + 2 * UNIT * abs(b)
        else:
            tol = 0.0
        assert abs(a - b) <= tol, f"{where}: {var.name} native {a!r}, Python {b!r}"


@pytest.mark.parametrize(("ident", "params"), CASES)
def test_native_controller_equals_python_core(natives, ident, params):
    """Every output after every call, bit for bit: steps of the sample time and irregular
    ones (shorter, longer, across several events: inputs held), and inputs set again at an
    event instant before the step (an iterating master)."""
    pair = Pair(natives, ident, params)
    rng = random.Random(zlib.crc32(repr((ident, sorted(params.items()))).encode()))
    names = [v.name for v in pair.inputs]
    sample = pair.py.values["sample_time"]
    t, executions = 0.0, 0
    for k in range(300):
        values = random_inputs(rng, ident, names)
        pair.set_inputs(values)
        native, py = pair.read()
        assert_outputs_agree(pair, ident, native, py, f"{ident} {params}: step {k} at t = {t}")
        if rng.random() < 0.3:  # the same instant again with other inputs
            pair.set_inputs([0.9 * x for x in values])
            native, py = pair.read()
            assert_outputs_agree(pair, ident, native, py, f"{ident} {params}: re-read at {t}")
        h = sample * rng.choice([1.0, 1.0, 0.5, 0.25, 1.85, 6.5, 10.0])
        pair.step(t, h)
        t += h
        executions = pair.read()[0][[v.name for v in pair.outputs].index("executions")]
    assert executions > 300  # events did run, inside long steps too


@pytest.mark.parametrize("ident", CONTROLLERS)
def test_strict_steps_refuses_a_step_over_an_event_in_both(natives, ident):
    pair = Pair(natives, ident, {"strict_steps": True})
    pair.set_inputs(random_inputs(random.Random(0), ident, [v.name for v in pair.inputs]))
    sample = pair.py.values["sample_time"]
    pair.step(0.0, sample)  # ends on the next event: allowed
    with pytest.raises(FMICallException):
        pair.native.doStep(sample, 1.5 * sample)
    with pytest.raises(ValueError, match="strict_steps"):
        pair.py.do_step(sample, 1.5 * sample)
    with pytest.raises(FMICallException):  # not continuing from the controller's time
        pair.native.doStep(3 * sample, sample)


@pytest.mark.parametrize("ident", CONTROLLERS)
def test_native_controller_state_is_complete(natives, ident):
    """Get the state mid-run (at an event instant with a tentative event shown), run on,
    restore it (and a serialized copy in a fresh instance): the same outputs again."""
    pair = Pair(natives, ident, {})
    fmu = pair.native
    rng = random.Random(7)
    names = [v.name for v in pair.inputs]
    t = 0.0
    for _ in range(20):
        pair.set_inputs(random_inputs(rng, ident, names))
        pair.step(t, 0.3)
        t += 0.3
    later = [(random_inputs(rng, ident, names), rng.choice([0.2, 0.5, 0.05])) for _ in range(30)]
    pair.set_inputs(later[0][0])
    fmu.getReal([pair.vars["next_event_time"].valueReference])  # shows a tentative event
    state = fmu.getFMUstate()
    blob = fmu.serializeFMUstate(state)

    def run(slave) -> list:
        out, tt = [], t
        for values, h in later:
            slave.setReal([v.valueReference for v in pair.inputs], values)
            out.append(slave.getReal([v.valueReference for v in pair.outputs
                                      if v.type == "Real"]))
            slave.doStep(tt, h)
            tt += h
        return out

    first = run(fmu)
    fmu.setFMUstate(state)
    assert run(fmu) == first
    md, unzipdir = natives[ident]
    other = FMU2Slave(guid=md.guid, unzipDirectory=unzipdir, instanceName="other",
                      modelIdentifier=md.coSimulation.modelIdentifier)
    other.instantiate()
    other.setFMUstate(other.deSerializeFMUstate(blob))
    assert run(other) == first
    fmu.freeFMUstate(state)


def test_native_speed_pid_refuses_a_reference_file_path(natives):
    md, unzipdir = natives["EmuSpeedPid3"]
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzipdir, instanceName="native",
                    modelIdentifier=md.coSimulation.modelIdentifier)
    fmu.instantiate()
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    vr = {v.name: v.valueReference for v in md.modelVariables}
    fmu.setString([vr["reference"]], ["/tmp/profile.csv"])
    with pytest.raises(FMICallException):
        fmu.exitInitializationMode()


# -- closed loops of the shipped scenarios -----------------------------------------------------
SHORT_S = 30.0
IRREPRODUCIBLE = ("*wall_time*", "*real_time*", "*solve_time*", "*cpu_time*")
# scenario -> the instances that have a native build
NATIVE_LOOPS = {
    "seed000_stop_pid": ("controller",),
    "seed000_stop_pid_plain": ("controller",),
    "seed001_emu_pid": ("controller",),
    "seed004_crh3_pid": ("controller",),
    "seed004_crh3_empc": ("controller",),
}
WITH_NATIVE_PLANT = ("seed000_stop_pid", "seed000_stop_pid_plain")  # BrakeDelayTrain


def _flat(summary: dict, prefix: str = "") -> dict:
    out = {}
    for key, value in summary.items():
        name = f"{prefix}{key}"
        if any(fnmatch.fnmatch(name, p) for p in IRREPRODUCIBLE):
            continue
        if isinstance(value, dict):
            out.update(_flat(value, name + "."))
        elif not (isinstance(value, float) and value != value):
            out[name] = value
    return out


def _compare(name: str, natives: tuple[str, ...], stop_time: float | None,
             d_force: float | None = None) -> None:
    """The scenario ``name`` with the instances ``natives`` native against all Python: bit for
    bit, or with ``d_force`` (N, the largest difference of a force between the two
    controllers at one event; the EMPC's :func:`empc_force_bound` when it is native) within
    n_events d_force relative to the run's mean force (module docstring)."""
    base = [] if stop_time is None else [f"simulation.stop_time={stop_time}"]
    py = run_scenario(name, base, plot=False)
    nat = run_scenario(name, base + [f"{c}.build=native" for c in natives], plot=False)
    cols = [c for c in py.frame.columns
            if not any(fnmatch.fnmatch(c, p) for p in IRREPRODUCIBLE)]
    s_py, s_nat = _flat(py.summary), _flat(nat.summary)
    assert s_py.keys() == s_nat.keys()
    sc = load_scenario(name, base)
    meaningful = 1e-3  # the bound is below any difference a claim rests on
    if d_force is None and any(sc.components[c].fmu == "Empc3" for c in natives):
        d_force, meaningful = empc_force_bound(), 1e-6  # far below any figure reported
    if d_force is None:  # bit for bit
        differing = [c for c in cols if not py.frame[c].equals(nat.frame[c])]
        assert not differing, f"{name} with native {natives}: differs in {differing[:5]}"
        assert {k: (v, s_nat[k]) for k, v in s_py.items() if v != s_nat[k]} == {}
        return
    # EMPC: n_events dF relative to the mean force (module docstring)
    n_events = sc.simulation.stop_time / sc.components["controller"].sample_time
    mean_force = float(py.frame["controller.force_demand"].abs().mean())
    rtol = n_events * d_force / mean_force
    assert rtol < meaningful
    # a coupler force k (x_i - x_i+1) + d (v_i - v_i+1) is a difference of two positions of
    # magnitude s_max: once the forces differ, each run rounds its positions its own way, by up
    # to u s_max per plant sub-step and position, so two runs' couplers may differ by
    # 2 k (2 n_sub u s_max) beyond what the force bound explains (plus d times the speeds')
    plant = sc.components["plant"]
    train = emu_config(str(plant.parameters["configuration"]))
    n_sub = sc.simulation.stop_time / float(plant.parameters["max_step"])
    s_max = float(py.frame["plant.s"].abs().max())
    v_scale = max(float(py.frame[c].abs().max()) for c in cols if c.startswith("plant.v["))
    coupler = (train.coupler_stiffness * 4 * n_sub * UNIT * s_max
               + train.coupler_damping * 2 * rtol * v_scale)
    for c in cols:
        a, b = py.frame[c].to_numpy(), nat.frame[c].to_numpy()
        if c == "controller.delta":
            assert (a == b).all(), f"{name}: the mode schedule differs"
        else:
            scale = float(np.abs(a).max())
            atol = rtol * scale + (coupler if c.startswith("plant.coupler_force[") else 0.0)
            assert np.allclose(b, a, rtol=rtol, atol=atol), f"{name}: {c}"
    for key, value in s_py.items():
        other = s_nat[key]
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            # a figure in m (distance short of the timetable) is a difference of positions:
            # it may differ by what the position column may, rtol s_max
            extra = (coupler * (1e-3 if key.endswith("_kn") else 1.0) if "coupler" in key
                     else rtol * s_max if key.endswith("_m") else 0.0)
            assert math.isclose(other, value, rel_tol=rtol, abs_tol=rtol + extra), (
                key, value, other)
        else:
            assert other == value, key


def _loops():
    for name, comps in NATIVE_LOOPS.items():
        yield name, comps
        if name in WITH_NATIVE_PLANT:
            yield name, (*comps, "plant")


@pytest.mark.parametrize(("name", "comps"), list(_loops()))
def test_shipped_loop_with_native_controller_equals_python(name, comps):
    if shutil.which("gcc") is None:
        pytest.skip("gcc not installed: native FMUs cannot be built")
    stop = load_scenario(name).simulation.stop_time
    _compare(name, comps, min(stop, SHORT_S))


@pytest.mark.slow
@pytest.mark.parametrize(("name", "comps"), list(_loops()))
def test_whole_shipped_loop_with_native_controller_equals_python(name, comps):
    if shutil.which("gcc") is None:
        pytest.skip("gcc not installed: native FMUs cannot be built")
    _compare(name, comps, None)


def test_build_option_errors_name_the_key():
    with pytest.raises(ScenarioError, match=r"--set controller.build=native: build = "
                       r"'native': 'Crh3LmiMpc' has no native model"):
        load_scenario("seed003_crh3_lmimpc_conventional", ["controller.build=native"])
    with pytest.raises(ScenarioError, match=r"build = 'cpp'.*expected one of"):
        load_scenario("seed000_stop_pid", ["controller.build=cpp"])
    sc = load_scenario("seed000_stop_pid", ["plant.build=native", "controller.build=native"])
    assert {c.fmu_path.parent.name for c in sc.components.values()} == {"native"}
    sc = load_scenario("seed000_stop_pid", ["controller.build=native",
                                            "simulation.fmi_version=3"])
    assert sc.components["controller"].fmu_path == native_path("StopPid", 3)


@pytest.mark.parametrize(("ident", "params", "message"), [
    ("StopPid", {"u_min": 50.0, "u_max": 40.0}, "u_min = 50.0 must be < u_max = 40.0"),
    ("EmuSpeedPid3", {"accel_min": 1.0, "accel_max": 0.5},
     "accel_min = 1.0 must be < accel_max = 0.5"),
    ("Empc3", {"N": 5}, "move_blocks = '3:4:3': positive lengths summing to N = 5"),
    ("Empc3", {"N": 5, "move_blocks": "5"},
     "regions = 'seed004_empc_crh3_3car.npz' were built for N = 10.0, this controller has 5.0"),
    ("Empc3", {"configuration": "crh380a_3unit"}, "were built for configuration = crh3_3car, "
     "this controller has 'crh380a_3unit'"),
    ("Empc3", {"dR": 0.5}, "dR = 0.5: the EMPC's reduced problem has no force-increment term"),
    ("Empc3", {"R": 0.0}, "R = 0.0, dR = 0.0: both >= 0 and one > 0"),
    ("Empc3", {"evaluation": "lookup"}, "evaluation = 'lookup' must be one of ('explicit', "
     "'online')"),
])
def test_bad_parameters_are_refused_by_both(natives, ident, params, message):
    md, unzipdir = natives[ident]
    vr = {v.name: v for v in md.modelVariables}
    logged: list[str] = []

    def logger(component, instance, status, category, text):
        logged.append(text.decode())

    fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzipdir, instanceName="native",
                    modelIdentifier=md.coSimulation.modelIdentifier)
    fmu.instantiate(callbacks=_callbacks(logger))
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    py = catalog()[ident].load()(instance_name="python", resources=tempfile.mkdtemp())
    for name, value in params.items():
        ref = [vr[name].valueReference]
        if vr[name].type == "Integer":
            fmu.setInteger(ref, [value])
            py.set_integer(ref, [value])
        elif vr[name].type == "String":
            fmu.setString(ref, [value])
            py.set_string(ref, [value])
        else:
            fmu.setReal(ref, [value])
            py.set_real(ref, [value])
    with pytest.raises(FMICallException):
        fmu.exitInitializationMode()
    assert any(message in text for text in logged), logged
    py.setup_experiment(0.0)
    py.enter_initialization_mode()
    with pytest.raises(ValueError, match=re.escape(message)):
        py.exit_initialization_mode()


def _callbacks(logger):
    from fmpy.fmi2 import defaultCallbacks, fmi2CallbackFunctions, fmi2CallbackLoggerTYPE

    cb = fmi2CallbackFunctions()
    cb.logger = fmi2CallbackLoggerTYPE(logger)
    cb.allocateMemory = defaultCallbacks.allocateMemory
    cb.freeMemory = defaultCallbacks.freeMemory
    return cb
