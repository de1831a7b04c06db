"""The native C freight controller FMUs (FreightPid, FreightSmc, FreightFpid, FreightPreview: a law
file over cosim/fmu/native/controllers/freight_tracker.c, the shared observer and blending, behind
controller_backend.c) against their Python cores, and the shipped seed-002 closed loops with the
native plant and controller against the all-Python loops.

Tolerance. The C files are compiled -std=c99 -ffp-contract=off and perform the cores' IEEE
double operations in the cores' order (scalar arithmetic, sqrt, exp and libm pow, numpy.interp
and numpy's pairwise sum written out), with three kinds of exceptions, each bounded per call:

* numpy's dot and matrix-vector products (BLAS: blocked, possibly fused multiply-add, in an
  order of its own), which the C sums in index order: the observer's ``A z`` (n = 5), the
  brake forces ``sum brake_scale_i p_i`` (n = 109, non-negative terms) of the observer's input,
  the blending's air-brake trim and the predicted stop's air schedule. Two orders of n
  products differ by at most 2 gamma_n sum |x_i y_i| (gamma_n = n u / (1 - n u), u = 2^-53;
  Higham, Accuracy and Stability of Numerical Algorithms, eq. 3.5, any order, with or
  without FMA): at most 2 gamma_109 relative for the brake sums, 2 gamma_5 for A z;
* numpy's pow over arrays in the brake-cylinder filling of the blending's brake-pipe model
  (numpy's SIMD pow where the CPU has it, within 4 ulp by numpy's accuracy tests of its SIMD
  float64 functions), against glibc's pow (within 1 ulp): 5 ulp, 10 u relative, per call,
  two calls per cylinder and step;

so one event's outputs differ from the core's at the same state by at most
EPS = 2 gamma_109 + 2 gamma_5 + 20 u relative to their scale (:data:`EPS`). The preview servo
has three more dot products, ``F0 x0 + F_R Delta R + F_d Delta d`` (n <= 151, terms of both
signs): its increment differs by at most 2 gamma_151 S, S the sum of the terms' magnitudes,
which the test records from the core's own products at every event (:class:`TermScale`), so
its EPS is EPS + 2 gamma_151 max S / scale. The state the
events carry (observer speed and bias, cylinder pressures, the law's integral) holds the
difference on; counting it as never damped and integrated once more by the law's integral,
after k events the difference is at most (k + 1)^2 EPS of the output's largest magnitude over
the run (:func:`bound`). Discrete outputs (the pipe reduction: stages, holding, the final
approach) are compared exactly: a different decision would need a quantity within that bound
of its threshold, and the test says so if one does. The reference speed and acceleration and
the speed error depend on the inputs alone and are compared exactly too. In closed loop the
plant's native twin gives the Python core's outputs (tests/test_native_freight.py), and the
summaries of the whole run are held to n_events^2 EPS (the stop error and positions to it of
the stop point).
"""

from __future__ import annotations

import fnmatch
import math
import shutil
from pathlib import Path

import numpy as np
import pytest
from fmi_state_helpers import FmuInstance, rerun_after_restore
from freight_loop import closed_loop
from native_helpers import set_by_type
from test_native_controllers import _callbacks, _flat, gamma

from controllers.preview.preview import PreviewParams
from cosim.build.python import catalog
from cosim.run.scenario import load_scenario
from cosim.run.simulate import run_scenario

ROOT = Path(__file__).resolve().parents[1]
U = 2.0**-53
EPS = 2 * gamma(109) + 2 * gamma(5) + 20 * U
CONTROLLERS = ("FreightPid", "FreightSmc", "FreightFpid", "FreightPreview")
OUTPUTS = ("force_demand", "pipe_reduction", "accel_demand", "v_ref", "a_ref", "speed_error",
           "air_brake_estimate", "v_mean_estimate")
EXACT = ("pipe_reduction", "v_ref", "a_ref", "speed_error")
SAMPLE = 0.2  # s, the controllers' default sample time (the native observer's design model)


def bound(k: int) -> float:
    """Largest relative difference (of the output's scale) after k events (module doc)."""
    return (k + 1) ** 2 * EPS


@pytest.fixture(scope="module")
def natives(native_builds):
    return {ident: native_builds(ident)[2] for ident in CONTROLLERS}


def core_of(ident: str, params: dict | None = None):
    slave = catalog()[ident].load()
    values = {v.name: v.start for v in slave.variables if v.causality == "parameter"}
    values.update(params or {})
    return slave.core_class.from_parameters(values, ROOT)


def final_braking_start(core, before: float = 150.0) -> tuple[float, float]:
    """(s0, v0): where and how fast the reference is ``before`` s before it ends (the final
    braking with the planned air-brake application, the final approach and the hold)."""
    profile = core.profile
    times = profile.times()
    t0 = float(times[np.isfinite(times)][-1]) - before
    s0 = float(np.interp(t0, times[np.isfinite(times)], profile.x[np.isfinite(times)]))
    return s0, profile.speed(s0)


def recorded_inputs(ident: str, t_end: float, s0: float = 0.0, v0: float = 0.0):
    """(t, v, s) of each event of the core's closed loop on the freight plant core."""
    core = core_of(ident)
    loop = closed_loop(core, core.route, t_end, SAMPLE, s0=s0, v0=v0)
    return list(zip(loop["t"].tolist(), loop["v"].tolist(), loop["s"].tolist()))


def open_native(path: Path, name: str = "native") -> FmuInstance:
    return FmuInstance(str(path), name, strings={"route": "freight_20km"})


class TermScale:
    """A gain vector whose ``@`` is numpy's own (the same product, so the core's results do
    not change) and which records sum |F_j y_j|, the scale of its rounding error."""

    def __init__(self, gains: np.ndarray, record: list[float]) -> None:
        self.gains, self.record = gains, record

    def __getitem__(self, i: int) -> TermScale:
        return TermScale(self.gains[i], self.record)

    def __matmul__(self, y: np.ndarray) -> float:
        self.record.append(float(np.abs(self.gains) @ np.abs(y)))
        return self.gains @ y


def record_preview_terms(core) -> list[float]:
    """Make the preview core record its servo's term magnitudes (three per event)."""
    from dataclasses import replace

    terms: list[float] = []
    g = core.gains
    core.gains = replace(g, F0=TermScale(g.F0, terms), FR=TermScale(g.FR, terms),
                         Fd=TermScale(g.Fd, terms))
    return terms


def compare_replay(path: Path, ident: str, inputs: list) -> dict[str, float]:
    """A fresh core and the native FMU given the same inputs at every event: the outputs of
    each event within :func:`bound` (the exact ones equal). Returns the coverage."""
    core = core_of(ident)
    terms = record_preview_terms(core) if ident == "FreightPreview" else []
    fmu = open_native(path)
    rows_core, rows_native = [], []
    for t, v, s in inputs:
        expected, _ = core.compute(t, {"v": v, "s": s})
        fmu.set(["v", "s"], [v, s])
        rows_native.append(fmu.get(list(OUTPUTS)))
        fmu.fmu.doStep(t, SAMPLE)
        rows_core.append([expected[n] for n in OUTPUTS])
    fmu.fmu.terminate()
    fmu.fmu.freeInstance()
    a, b = np.array(rows_core), np.array(rows_native)
    for j, name in enumerate(OUTPUTS):
        if name in EXACT:
            differ = np.nonzero(a[:, j] != b[:, j])[0]
            assert differ.size == 0, (f"{ident}.{name} differs first at t = "
                                      f"{inputs[differ[0]][0]}: {b[differ[0], j]!r} != "
                                      f"{a[differ[0], j]!r}")
            continue
        scale = float(np.abs(a[:, j]).max())
        eps = EPS
        if terms and name in ("force_demand", "accel_demand"):  # the servo's dot products
            per_event = np.add.reduceat(np.array(terms), np.arange(0, len(terms), 3))
            unit = core.m_eff if name == "force_demand" else 1.0  # N per m/s^2
            eps = EPS + 2 * gamma(151) * float(per_event.max()) * unit / scale
        tol = np.array([(k + 1) ** 2 * eps for k in range(len(inputs))]) * scale
        over = np.nonzero(np.abs(b[:, j] - a[:, j]) > tol)[0]
        assert over.size == 0, (f"{ident}.{name} beyond the bound first at t = "
                                f"{inputs[over[0]][0]}: {b[over[0], j]!r} vs {a[over[0], j]!r}")
    red = a[:, OUTPUTS.index("pipe_reduction")]
    return {"applied": float((red > 0).any()), "released": float(((red[:-1] > 0)
                                                                   & (red[1:] == 0)).any()),
            "held": float(red[-1]), "air": float(a[:, OUTPUTS.index("air_brake_estimate")].max())}


@pytest.mark.parametrize("ident", CONTROLLERS)
def test_native_equals_python_core_over_the_final_braking(natives, ident):
    """The last 150 s of the seed-002 reference from its state there: the planned air-brake
    application, the final approach (air released) and the holding brake at the stop."""
    s0, v0 = final_braking_start(core_of(ident))
    inputs = recorded_inputs(ident, 160.0, s0, v0)
    seen = compare_replay(natives[ident], ident, inputs)
    assert seen["applied"] and seen["air"] > 0, seen
    assert seen["held"] > 0, seen  # the holding brake at the end


@pytest.mark.slow
@pytest.mark.parametrize("ident", CONTROLLERS)
def test_native_equals_python_core_over_the_whole_run(natives, ident):
    compare_replay(natives[ident], ident, recorded_inputs(ident, 1400.0))


@pytest.mark.parametrize("ident", CONTROLLERS)
def test_native_state_round_trip(natives, ident):
    """getFMUstate / serialize, run on, restore from the bytes, run again: the same outputs
    exactly, across the air-brake application (the brake-pipe history is part of the
    state)."""
    s0, v0 = final_braking_start(core_of(ident))
    inputs = recorded_inputs(ident, 160.0, s0, v0)
    fmu = open_native(natives[ident])

    def step(k: int) -> list[float]:
        t, v, s = inputs[k]
        fmu.set(["v", "s"], [v, s])
        fmu.fmu.doStep(t, SAMPLE)
        return fmu.get(list(OUTPUTS))

    first, second = rerun_after_restore([fmu], step, 100, len(inputs))
    assert first == second
    assert any(row[OUTPUTS.index("pipe_reduction")] > 0 for row in first)


M_R = PreviewParams().preview_steps  # the declared (tuned) reference preview of the design


@pytest.mark.parametrize(("ident", "params", "message"), [
    ("FreightPid", {"sample_time": 0.1}, "sample_time = 0.1: the native FMU carries the "
     "mean-speed observer's design model for sample_time = 0.2 only"),
    ("FreightSmc", {"q": 6.0}, "q T = 1.2000000000000002 must be in [0, 1)"),
    ("FreightFpid", {"fuzzy_nodes": 21}, "fuzzy_nodes = 21.0: the native FMU carries the rule "
     "surfaces on 13 nodes per axis only"),
    ("FreightPid", {"route": "routes/freight_20km.toml"}, "route = 'routes/freight_20km.toml':"
     " the native FMU knows the bundled routes"),
    ("FreightPid", {"release_share": 0.9}, "need 0 < release_share (0.9) < ed_share (0.8)"),
    ("FreightPreview", {"M_R": M_R + 1}, f"M_R = {float(M_R + 1)}: the native FMU carries the "
     f"preview gains of the default design (M_R = {float(M_R)}) only"),
])
def test_native_refuses_what_it_cannot_run(natives, ident, params, message):
    """Parameters the native FMU does not carry data for, or that the core refuses, are
    refused at initialisation with a message naming the parameter."""
    from fmpy import extract, read_model_description
    from fmpy.fmi1 import FMICallException
    from fmpy.fmi2 import FMU2Slave

    path = str(natives[ident])
    md = read_model_description(path)
    var = {v.name: v for v in md.modelVariables}
    logged: list[str] = []
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=extract(path), instanceName="native",
                    modelIdentifier=md.coSimulation.modelIdentifier)
    fmu.instantiate(callbacks=_callbacks(lambda c, i, s, cat, text: logged.append(
        text.decode())))
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.setString([var["route"].valueReference], ["freight_20km"])
    set_by_type(fmu, md, params)
    with pytest.raises(FMICallException):
        fmu.exitInitializationMode()
    assert any(message in text for text in logged), logged


# -- closed loops of the shipped seed-002 scenarios ---------------------------------------------
IRREPRODUCIBLE = ("*wall_time*", "*real_time*", "*solve_time*", "*cpu_time*")
LOOPS = {"FreightPid": "seed002_freight_pid", "FreightSmc": "seed002_freight_smc",
         "FreightFpid": "seed002_freight_fpid", "FreightPreview": "seed002_freight_preview"}


def preview_term_scale(frame) -> float:
    """Largest sum |F y| of the preview servo's products over the loop's events, relative to
    its largest demand: the core replayed on the loop's measured speeds and positions."""
    core = core_of("FreightPreview")
    terms = record_preview_terms(core)
    for t, v, s in zip(frame["time"], frame["plant.v"], frame["plant.s"]):
        core.compute(float(t), {"v": float(v), "s": float(s)})
    per_event = np.add.reduceat(np.array(terms), np.arange(0, len(terms), 3))
    return float(per_event.max()) / float(frame["controller.accel_demand"].abs().max())


def compare_loops(name: str, stop_time: float | None) -> None:
    """All-Python loop against native plant + native controller: every recorded series and
    every summary within n_events^2 EPS of its scale (module doc); the pipe reduction equal."""
    base = [] if stop_time is None else [f"simulation.stop_time={stop_time}"]
    py = run_scenario(name, base, plot=False)
    nat = run_scenario(name, base + ["plant.build=native", "controller.build=native"],
                       plot=False)
    sc = load_scenario(name, base)
    n_events = sc.simulation.stop_time / sc.components["controller"].sample_time
    eps = EPS
    if sc.components["controller"].fmu == "FreightPreview":  # the servo's dot products
        eps += 2 * gamma(151) * preview_term_scale(py.frame)
    rtol = n_events**2 * eps
    assert rtol < 1e-5  # meaningful: far below any figure a summary reports
    for c in py.frame.columns:
        if any(fnmatch.fnmatch(c, p) for p in IRREPRODUCIBLE):
            continue
        a, b = py.frame[c].to_numpy(), nat.frame[c].to_numpy()
        if c == "controller.pipe_reduction":
            assert (a == b).all(), f"{name}: the brake applications differ"
        else:
            assert np.allclose(b, a, rtol=0.0, atol=rtol * float(np.abs(a).max())), f"{name}: {c}"
    s_py, s_nat = _flat(py.summary), _flat(nat.summary)
    assert s_py.keys() == s_nat.keys()
    stop_point = float(sc.summary["stop_point"])  # m, the scale of positions
    for key, value in s_py.items():
        other = s_nat[key]
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            scale = stop_point if key.endswith("_m") else 1.0
            assert math.isclose(other, value, rel_tol=rtol, abs_tol=rtol * scale), \
                (key, value, other)
        else:
            assert other == value, key


def test_seed002_pid_loop_with_native_plant_and_controller_equals_python():
    if shutil.which("gcc") is None:
        pytest.skip("gcc not installed: native FMUs cannot be built")
    compare_loops("seed002_freight_pid", 60.0)


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(LOOPS.values()))
def test_whole_seed002_loop_with_native_plant_and_controller_equals_python(name):
    if shutil.which("gcc") is None:
        pytest.skip("gcc not installed: native FMUs cannot be built")
    compare_loops(name, None)


