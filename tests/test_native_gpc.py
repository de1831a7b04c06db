"""The native C FMU of seed 003's GPC tracker Crh3Gpc (cosim/fmu/native/controllers/crh3_gpc.c over
gpc.c, the GPC numerics it shares with seed 001's EmuGpc3) against the Python FMU of its
core (controllers.eco.gpc.Crh3Gpc) on the inputs of the shipped seed-003 GPC scenarios, and the
shipped closed loops with the native controller against the Python one.

What is equal bit for bit. The target profile is planned by the Python planner at build time
and shipped exactly (repr, read back by strtod); its sampling (at_time, at_position,
phase_at_time), the references, the input box and the holding brake are the core's scalar
operations in its order (-std=c99 -ffp-contract=off; libm's pow and sqrt as CPython's), so
v_ref, a_ref, s_ref, phase, speed_error and next_event_time are compared exactly. What differs
by rounding: the products numpy forms with BLAS (P x, x'P x, theta x, G'G, G'(R - f); other
summation orders, fused multiply-adds) and the 2 x 2 solve (LAPACK's dgesv; C: Gaussian
elimination with the same pivoting), so u and the GPC's state differ by rounding.

Bound of one sample, from the same state. The longest chain of roundings of a sample is below
64: the RLS update (|x|, P x, x'P x, the gain, the innovation, the theta and P updates, the
symmetrisation and the trace cap: 26), the predictions (3 steps of 4), G'G + w I and G'(R - f)
(3-term sums), the 2 x 2 elimination and u = u_prev + du. So each side computes the exact sample
of a state whose blocks (theta, P, y_prev, dy_hist, du_hist, u_prev) are perturbed by at most
EPS = 64 u times their norm (backward error: a sum of products errs by gamma_k relative to the
sum of |terms|; Higham, Accuracy and Stability of Numerical Algorithms, ch. 3). A state value
then differs by at most 2 EPS sum_B |B| sum_(i in B) |d value / d B_i| (first order, both sides
err; the derivatives by forward differences on the Python core, coordinate by coordinate: the
state has ten) plus 2 EPS |value| (its own last rounding), plus on the entries that hold the
move (force, u, u_prev, du(t) in du_hist) the forward error of the backward-stable solve, 2 EPS
cond(G'G + w I) |dU|, which a perturbation of the state does not reach when the system is
ill-conditioned. A clip of u at the input box crossed by a perturbation shows as a large
derivative (conservative).

The closed loop. The single mass under the GPC does not amplify a rounding-level change of the
force (the tracking error decays within a few samples), so the loop's differences are those of
the samples added up: every recorded value and summary figure within rtol = (sum over the
samples of the one-sample force bound) / (mean |force|) of its scale (a relative change of the
force moves the speeds, positions and energies by the same relative order).

The C hosts without Python, fmpy, the compliance suite (FMI 2.0 and 3.0) and Wine run over this
FMU with every native one in tests/test_native_hosts.py.
"""

from __future__ import annotations

import copy
import dataclasses
import fnmatch
import functools
import math
import tempfile

import numpy as np
import pytest
from fmpy.fmi1 import FMICallException
from native_helpers import build_unzipped, law_doubles, open_native, set_law_doubles

from cosim.build.python import catalog

IDENT = "Crh3Gpc"
UNIT = 2.0**-53
EPS = 64 * UNIT  # backward error of a sample's blocks (module docstring)
H = 2.0**-20  # forward-difference step, relative to a block's norm
SCENARIOS = ("seed003_crh3_gpc_eco", "seed003_crh3_gpc_conventional",
             "seed003_crh3_gpc_cruise", "seed003_crh3_gpc_optimal")
INPUTS = ("v", "s", "traction_limit", "brake_limit")  # the plant's outputs of the same names
GPC_BLOCKS = ("theta", "P", "y_prev", "dy_hist", "du_hist", "u_prev")
EXACT_OUTPUTS = ("v_ref", "a_ref", "s_ref", "speed_error", "phase", "next_event_time")
DEFAULT_STRIDE = 25  # every 25th sample of the eco run in the default suite
TIMING = ("*wall_time*", "*real_time*", "*solve_time*", "*cpu_time*")


@pytest.fixture(scope="module")
def native(tmp_path_factory, native_builds):
    return build_unzipped(IDENT, tmp_path_factory, native_builds)


@functools.cache
def python_loop(scenario: str):
    """The shipped closed loop with the Python controller and the native plant (equal to the
    Python plant bit for bit, tests/test_native_plants.py), the controller's inputs recorded."""
    from cosim.run.scenario import load_scenario
    from cosim.run.simulate import run_scenario

    sc = load_scenario(scenario, ["plant.build=native"])
    sc = dataclasses.replace(sc, record=[*(sc.record or []),
                                         *(f"plant.{n}" for n in INPUTS if n != "v")])
    return run_scenario(sc, plot=False)


def recorded_inputs(scenario: str) -> tuple[np.ndarray, np.ndarray]:
    """(times, inputs (samples, 4)): the controller's inputs at its samples."""
    frame = python_loop(scenario).frame
    return (frame["time"].to_numpy(),
            np.column_stack([frame[f"plant.{n}"].to_numpy() for n in INPUTS]))


def law_state(state: dict) -> np.ndarray:
    """The Python core's state as the native law's doubles (crh3_gpc.c's order)."""
    g = state["gpc"]
    parts = [[state[k] for k in ("force", "u", "v_ref", "a_ref", "s_ref", "speed_error")],
             [float(state["phase"]), float(state["holding"])],
             *(g[k] for k in GPC_BLOCKS), [float(g["started"]), float(g["updates"])]]
    return np.concatenate([np.asarray(p, float).ravel() for p in parts])


def move_marks(state: dict) -> np.ndarray:
    """1 at the law state's entries that hold the sample's move (force, u, u_prev, du(t))."""
    marked = {**{k: 0.0 for k in state if k != "gpc"}, "force": 1.0, "u": 1.0,
              "gpc": {k: np.zeros_like(np.asarray(v, float)) for k, v in state["gpc"].items()}}
    marked["gpc"]["u_prev"][:] = 1.0
    marked["gpc"]["du_hist"][0] = 1.0
    return law_state(marked)


def solve_error(core, state: dict, t: float, inputs: dict) -> float:
    """2 EPS cond(A) |dU| of the sample's A dU = G'(R - f), A = G'G + w I; 0 at a holding
    sample (no solve)."""
    core.set_state(state)
    calls = []
    gpc = core.gpc
    plan = type(gpc).plan

    def recording(refs):
        f, G = gpc.prediction_matrices()
        A = G.T @ G + gpc.p.control_weight * np.eye(G.shape[1])
        calls.append((A, np.linalg.solve(A, G.T @ (np.asarray(refs, float).ravel() - f))))
        return plan(gpc, refs)

    gpc.plan = recording
    try:
        core.compute(t, inputs)
    finally:
        del gpc.plan
    if not calls:
        return 0.0
    A, dU = calls[0]
    return 2 * EPS * float(np.linalg.cond(A)) * float(np.linalg.norm(dU))


def one_sample_bound(core, state: dict, t: float, inputs: dict) -> np.ndarray:
    """Per value of the law state after the sample: the module docstring's bound, the
    derivatives by forward differences on the core (a probe, not the twin)."""
    def run(s: dict) -> np.ndarray:
        core.set_state(s)
        core.compute(t, inputs)
        return law_state(core.get_state())

    base = run(state)
    total = np.zeros_like(base)
    for key in GPC_BLOCKS:
        block = np.asarray(state["gpc"][key], float)
        norm = float(np.linalg.norm(block))
        if norm == 0.0 or not math.isfinite(norm):
            continue
        for i in range(block.size):
            moved = {**state, "gpc": {**state["gpc"], key: block.copy()}}
            moved["gpc"][key].flat[i] += H * norm
            total += np.abs(run(moved) - base) / H  # |d value / d B_i| |B|
    bound = 2 * EPS * (total + np.abs(base))
    return bound + solve_error(core, state, t, inputs) * move_marks(state)


class Twins:
    """The native FMU and the Python FMU of Crh3Gpc with a scenario's controller parameters."""

    def __init__(self, native, params: dict) -> None:
        self.native, vr = open_native(native, params)
        self.py = catalog()[IDENT].load()(instance_name="python", resources=tempfile.mkdtemp())
        self.py.setup_experiment(0.0)
        self.py.enter_initialization_mode()
        for name, value in params.items():
            setter = self.py.set_string if isinstance(value, str) else self.py.set_real
            setter([vr[name]], [value])
        self.py.exit_initialization_mode()
        self.in_vrs = [vr[n] for n in INPUTS]
        self.out_names = [v.name for v in native[1].modelVariables
                          if v.causality == "output" and v.type == "Real"]
        self.out_vrs = [vr[n] for n in self.out_names]

    def sync_native(self) -> None:
        """Set the native law state to the Python core's."""
        set_law_doubles(self.native, law_state(self.py.core.get_state()))

    def sample(self, t: float, h: float, values) -> tuple[np.ndarray, np.ndarray]:
        """Both twins' outputs of the event at t from ``values``, then a step of h."""
        values = [float(x) for x in values]
        self.native.setReal(self.in_vrs, values)
        self.py.set_real(self.in_vrs, values)
        out = (np.array(self.native.getReal(self.out_vrs)),
               np.array(self.py.get_real(self.out_vrs)))
        self.native.doStep(t, h)
        self.py.do_step(t, h)
        return out


def controller_parameters(scenario: str) -> dict:
    from cosim.run.scenario import load_scenario

    return dict(load_scenario(scenario).components["controller"].parameters)


def compare_samples(native, scenario: str, stride: int = 1) -> tuple[int, float]:
    """Every ``stride``-th sample of the shipped scenario from the same state (module
    docstring; the twins step and synchronise at every sample); returns (samples compared,
    the sum over them of the force's bound)."""
    times, values = recorded_inputs(scenario)
    twins = Twins(native, controller_parameters(scenario))
    probe = None
    compared, force_bounds = 0, 0.0
    for k in range(len(times) - 1):
        t, h = float(times[k]), float(times[k + 1] - times[k])
        core = twins.py.core
        twins.sync_native()
        if k % stride:  # not compared: both twins step from one state
            twins.sample(t, h, values[k])
            continue
        before = core.get_state()
        probe = probe or copy.deepcopy(core)  # the derivatives' runs leave the twin alone
        bound = one_sample_bound(probe, before, t, dict(zip(INPUTS, map(float, values[k]))))
        native_out, py_out = twins.sample(t, h, values[k])
        after = law_state(core.get_state())
        got = law_doubles(twins.native, after.size)
        bad = np.flatnonzero(~(np.abs(got - after) <= bound))
        assert bad.size == 0, (f"{scenario} at t = {t}: state values {bad.tolist()} native "
                               f"{got[bad].tolist()}, Python {after[bad].tolist()}, bound "
                               f"{bound[bad].tolist()}")
        for name, a, b in zip(twins.out_names, native_out, py_out):
            tol = {"force": bound[0], "accel_demand": bound[1]}.get(name, 0.0)
            assert name in EXACT_OUTPUTS or tol > 0.0 or a == b, name
            assert abs(a - b) <= tol, f"{scenario} at t = {t}: {name} native {a!r}, Python {b!r}"
        force_bounds += float(bound[0])
        compared += 1
    return compared, force_bounds


def test_native_sample_equals_python_within_rounding(native):
    """Every DEFAULT_STRIDE-th sample of the eco run (start, coasting and re-acceleration,
    final braking, the hold at the stop) from the same state."""
    times, _ = recorded_inputs(SCENARIOS[0])
    compared, _ = compare_samples(native, SCENARIOS[0], DEFAULT_STRIDE)
    assert compared == len(range(0, len(times) - 1, DEFAULT_STRIDE))


def flat(summary: dict) -> dict:
    """A nested summary as one level (keys joined by "."), its timing entries left out."""
    import pandas as pd

    row = pd.json_normalize(summary, sep=".").iloc[0].to_dict()
    return {k: v for k, v in row.items() if not any(fnmatch.fnmatch(k, p) for p in TIMING)}


@pytest.mark.slow
@pytest.mark.parametrize("scenario", SCENARIOS)
def test_shipped_closed_loop_with_native_controller(native, scenario):
    """Every sample of the shipped run from the same state, then the whole closed loop with
    the native controller against the Python one on every recorded value and summary metric
    (energy per phase, tracking, stop and arrival errors) within the rtol of the module
    docstring."""
    from cosim.run.simulate import run_scenario

    times, _ = recorded_inputs(scenario)
    compared, force_bounds = compare_samples(native, scenario)
    assert compared == len(times) - 1
    py = python_loop(scenario)
    nat = run_scenario(scenario, ["plant.build=native", "controller.build=native"], plot=False)
    rtol = force_bounds / float(py.frame["controller.force"].abs().mean())
    assert rtol < 1e-6  # the bound is far below any figure a summary reports
    for col in nat.frame.columns:
        if any(fnmatch.fnmatch(col, p) for p in TIMING):
            continue
        a, b = py.frame[col].to_numpy(), nat.frame[col].to_numpy()
        assert np.all(np.abs(a - b) <= rtol * float(np.abs(a).max())), f"{scenario}: {col}"
    s_py, s_nat = flat(py.summary), flat(nat.summary)
    assert s_py.keys() == s_nat.keys()
    for key, value in s_py.items():
        other = s_nat[key]
        if isinstance(value, float) and not isinstance(value, bool):
            assert math.isclose(other, value, rel_tol=rtol, abs_tol=rtol), (key, value, other)
        else:
            assert other == value, key


@pytest.mark.parametrize(("params", "named"), [
    ({"mass": 900e3}, "mass = 900000.0"),
    ({"scheduled_time": 2200.0}, "scheduled_time = 2200.0"),
    ({"profile": "eco", "traction_share": 0.8}, "traction_share = 0.8"),
    ({"route": "seed004_level"}, "route = 'seed004_level'"),
    ({"route": "my/line.toml"}, "route = 'my/line.toml'"),
    ({"profile": "pmp", "optimum": "elsewhere/optimum.csv"},
     "optimum = 'elsewhere/optimum.csv'"),
    ({"profile": "pmp", "optimum": "no_such_optimum"}, "optimum = 'no_such_optimum'"),
    ({"profile": "steady"}, "profile = 'steady'"),
    ({"model_start": "warm"}, "model_start = 'warm'"),
    ({"Ny": 2, "Nu": 3}, "Nu = 3 must be <= Ny = 2"),
])
def test_a_profile_the_build_did_not_plan_is_refused_naming_the_parameter(native, params,
                                                                         named):
    """The shipped profiles are planned with the declared defaults: another value of a
    parameter they are planned with, a route or optimum not shipped or a file path is refused
    when the instance leaves initialisation, with a message naming the parameter and value."""
    messages: list[str] = []
    with pytest.raises(FMICallException):
        open_native(native, params, messages)
    assert any(named in m for m in messages), messages


def test_a_parameter_the_profile_does_not_depend_on_is_accepted(native):
    """position_gain and the GPC's own parameters leave the shipped profile usable; the first
    event's references are the profile's."""
    fmu, vr = open_native(native, {"position_gain": 0.05, "forgetting": 0.99,
                                   "profile": "cruise", "model_start": "cold"})
    fmu.setReal([vr["v"], vr["s"], vr["traction_limit"], vr["brake_limit"]],
                [0.0, 0.0, 3e5, 3e5])
    fmu.doStep(0.0, 1.0)
    assert fmu.getReal([vr["phase"]]) == [1.0]
    fmu.terminate()
    fmu.freeInstance()


def test_planning_fields_are_the_fields_train_and_settings_read():
    """Changing any other field of EcoTrackingParams leaves the planned train and settings
    unchanged; changing a planning field changes one of them."""
    from controllers.eco.tracking import EcoTrackingParams

    base = EcoTrackingParams()
    for field in dataclasses.fields(base):
        changed = dataclasses.replace(base, **{field.name: getattr(base, field.name) * 0.5
                                               - 0.25})
        same = (changed.train(), changed.settings()) == (base.train(), base.settings())
        assert same == (field.name not in base.planning_fields), field.name
