"""The native hybrid MPCs (Gmpc3, MbMpc3: cosim/fmu/native/controllers/hybrid_mpc.c over DAQP built
from its source distribution) against their Python cores (controllers/hybrid/hybrid_mpc.py,
miqp.py), sample by sample on the shipped seed 004 scenarios' inputs, and in the scenarios' closed
loops.

Lockstep: the plant core (Emu, the scenario's train and route) is driven by the Python
controller; at every sample both controllers get the plant's outputs as inputs and compute one
event. The mode applied (delta) and the counters of solves and infeasible events are compared
exactly. The branch-and-bound node count and the count of events solved only on a retry
(``qp_rescued``) are the path of DAQP's search, which a rounding-level difference of a
relaxation may change without changing the answer (seen in the degenerate big-M braking phase
of the whole runs: a few nodes in 700; at t = 619 s of the GMPC run the native first attempt
ends without a solution and its retry gives the answer), so they are not.

Force bound, derived per event from DAQP's tolerances and the problem's conditioning
(:func:`miqp_force_bound`): with the binaries fixed at the decided values the MIQP's answer is
the QP's, whose solution and multipliers z solve the KKT system K z = r of its working set W
(K = [[H, C_W'], [C_W, 0]], r = [-f; b_W]). Both sides form H, C, f, b from the same model
data in other summation orders (numpy's BLAS against index order) and factorise K in their own
(the Python wheel of DAQP is compiled with reassociation): each answer is then the exact one of
a system perturbed by |dK| <= eps |K|, |dr| <= eps |r|, eps = gamma_k (gamma_k = k u / (1 - k u),
u = 2^-53) with k = N (2 NX + NW) + nV the longest chain of rounded operations an entry passes
(N condensing steps, then the factorisation's sums). DAQP accepts a point whose constraints hold
to primal_tol, so the right-hand sides of W may also move by primal_tol each. The normwise
perturbation bound (Higham, Accuracy and Stability, thm 7.2) gives, per side,
||dz|| <= kappa(K) (eps (||z|| + ||r|| / ||K||) + primal_tol sqrt(|W|) / ||K||) / (1 - kappa eps),
so two answers differ by at most twice that; a force (N) by 1e3 times it (the QP is in kN).
The bound is asserted to be meaningful (below 1e-3 of the force envelope; it is largest,
up to about 1e-4 of it, where the envelope is power-limited).

Closed loop: as tests/test_native_controllers.py's EMPC loops, n_events times the largest
per-event bound, relative to the run's mean force, on every recorded column and every summary
figure the seed 004 claims use (energy, coupler forces, tracking, distance short), over the
first 30 s: over the whole 800 s run that accumulation (each event's bound counted as if the
loop never damped it) reaches percent and would test nothing, so whole runs are compared
sample by sample only.
"""

from __future__ import annotations

import math
import re
import tempfile

import daqp
import numpy as np
import pytest
from fmpy.fmi2 import FMU2Slave

from controllers.hybrid.hybrid_mpc import HybridMpc
from controllers.hybrid.miqp import _RETRY_SETTINGS
from controllers.hybrid.model import KN, Limits
from cosim.build.python import catalog
from cosim.fmu.state import to_ticks
from cosim.run.scenario import load_scenario
from plants.emu import Emu, emu_config
from plants.route import load_route
from tests.native_helpers import build_unzipped, initialising, set_by_type

IDENTS = ("Gmpc3", "MbMpc3")
SCENARIO = {"Gmpc3": "seed004_crh3_gmpc", "MbMpc3": "seed004_crh3_mbmpc"}
UNIT = 2.0**-53
PRIMAL_TOL = max([1e-6] + [s.get("primal_tol", 0.0) for s in _RETRY_SETTINGS])  # DAQP's


def gamma(n: int) -> float:
    return n * UNIT / (1 - n * UNIT)


@pytest.fixture(scope="module")
def natives(tmp_path_factory, native_builds):
    """identifier -> (FMU path, model description, unzipped folder), built once."""
    return {ident: build_unzipped(ident, tmp_path_factory, native_builds) for ident in IDENTS}


def miqp_force_bound(core: HybridMpc, t: float, inputs: dict[str, float]) -> float:
    """dF (N): the largest difference of one car's force between two answers to the event's
    MIQP (module docstring), for the Python core's state before the event (not changed)."""
    x0 = core.state_vector(inputs)
    n = core.n
    lim = Limits(np.array([max(inputs[f"traction_limit[{i}]"], 0.0) / KN
                           for i in range(1, n + 1)]),
                 np.array([max(inputs[f"brake_limit[{i}]"], 0.0) / KN for i in range(1, n + 1)]),
                 coupler=core.p.coupler_force_max / KN, speed=core.p.speed_max)
    done = core.braking_done
    delta = core.schedule(t, float(core.model.c @ x0))
    core.braking_done = done
    ref = core.references(t, float(inputs["s"]))
    u_prev = np.array(core.forces) / KN
    pb = core.miqp.for_modes(delta)
    res = pb.solve(x0, ref, lim, delta, u_prev)
    if not res.feasible:
        return math.inf  # the previous plan is applied: compared exactly by the caller
    f, _ = pb.linear_term(x0, ref, u_prev)
    lo, hi, _, _ = pb.bounds(x0, lim, delta)
    for i, _, _ in pb.binary_idx:  # the binaries at the decided values
        lo[i] = hi[i] = round(float(res.V[i]))
    hi = np.maximum(hi, lo)
    x, _, flag, info = daqp.solve(pb.H, f, pb.A, hi, lo, np.zeros(lo.size, np.int32))
    assert flag == 1
    lam = np.asarray(info["lam"])
    active = (lam != 0.0) | (lo == hi)
    C = np.vstack([np.eye(pb.nV), pb.A])[active]
    K = np.block([[pb.H, C.T], [C, np.zeros((C.shape[0], C.shape[0]))]])
    b = np.where(lam < 0.0, lo, hi)[active]
    z = np.concatenate([x, lam[active]])
    r = np.concatenate([-f, b])
    kappa = float(np.linalg.cond(K))
    norm_k = float(np.linalg.norm(K, 2))
    eps = gamma(pb.N * (2 * 2 * n + pb.md.nw) + pb.nV)
    assert kappa * eps < 0.5
    dz = kappa * (eps * (np.linalg.norm(z) + np.linalg.norm(r) / norm_k)
                  + PRIMAL_TOL * math.sqrt(C.shape[0]) / norm_k) / (1 - kappa * eps)
    return 2.0 * KN * float(dz)


def _instances(natives, ident: str, params: dict):
    path, md, unzipdir = natives[ident]
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzipdir, instanceName="native",
                    modelIdentifier=ident)
    fmu.instantiate()
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    py = catalog()[ident].load()(instance_name="python", resources=tempfile.mkdtemp())
    py.setup_experiment(0.0)
    py.enter_initialization_mode()
    for name, value in params.items():
        var = next(v for v in md.modelVariables if v.name == name)
        kind = {"Real": "real", "Integer": "integer", "Boolean": "boolean",
                "String": "string"}[var.type]
        value = int(value) if kind == "integer" else value
        getattr(fmu, f"set{kind.capitalize()}")([var.valueReference], [value])
        getattr(py, f"set_{kind}")([var.valueReference], [value])
    fmu.exitInitializationMode()
    py.exit_initialization_mode()
    return md, fmu, py


def lockstep(natives, ident: str, stop: float, overrides: dict) -> dict:
    """Run the shipped scenario's plant with the Python controller for ``stop`` s, both
    controllers computing every sample from the same inputs; assert the equalities and
    bounds of the module docstring; returns the largest bound and difference (N) and the
    events."""
    sc = load_scenario(SCENARIO[ident])
    params = {**sc.components["controller"].parameters, **overrides}
    md, fmu, py = _instances(natives, ident, params)
    plant_params = sc.components["plant"].parameters
    plant = Emu(emu_config(str(plant_params["configuration"])),
                load_route(str(plant_params["route"])))
    inputs = [v for v in md.modelVariables if v.causality == "input"]
    outputs = [v for v in md.modelVariables if v.causality == "output" and v.type == "Real"]
    names = [v.name for v in outputs]
    counters = [v for v in md.modelVariables if v.causality == "output" and v.type == "Integer"]
    exact = [i for i, v in enumerate(outputs) if not v.name.startswith("force")]
    ts = float(sc.components["controller"].sample_time)
    worst_bound = worst_diff = 0.0
    modes = set()
    events = int(round(stop / ts))
    for k in range(events):
        t = k * ts
        o = plant.outputs()
        values = {v.name: float(o[v.name]) for v in inputs}
        bound = miqp_force_bound(py.core, t, values)
        fmu.setReal([v.valueReference for v in inputs], list(values.values()))
        py.set_real([v.valueReference for v in inputs], list(values.values()))
        a = fmu.getReal([v.valueReference for v in outputs])
        b = py.get_real([v.valueReference for v in outputs])
        where = f"{ident} {overrides} at t = {t}"
        count = dict(zip([v.name for v in counters],
                         fmu.getInteger([v.valueReference for v in counters])))
        py_count = dict(zip(count, py.get_integer([v.valueReference for v in counters])))
        path = ("bnb_nodes", "qp_rescued")  # the search's path, not its answer
        assert {k: v for k, v in count.items() if k not in path} == \
            {k: v for k, v in py_count.items() if k not in path}, where
        assert [a[i] for i in exact if names[i] != "speed_error"] == \
            [b[i] for i in exact if names[i] != "speed_error"], where
        # speed error: the mean speed's dot product, 2 gamma_3 max |v| apart
        i_e = names.index("speed_error")
        assert abs(a[i_e] - b[i_e]) <= 2 * gamma(3) * max(values[f"v[{j}]"] for j in (1, 2, 3)) \
            + 2 * UNIT * abs(b[i_e]), where
        if math.isinf(bound):
            assert a == b, where
            continue
        envelope = max(abs(values[v.name]) for v in inputs if "limit" in v.name)
        assert bound <= 1e-3 * max(envelope, 1e4), f"{where}: the bound {bound} N is not " \
            "meaningful"
        for i, name in enumerate(names):
            if name.startswith("force["):
                assert abs(a[i] - b[i]) <= bound, f"{where}: {name} {a[i]!r} {b[i]!r} > {bound}"
                worst_diff = max(worst_diff, abs(a[i] - b[i]))
            elif name == "force_demand":
                assert abs(a[i] - b[i]) <= 3 * bound + 2 * gamma(3) * 3 * abs(b[i]), where
        worst_bound = max(worst_bound, bound)
        modes.add(b[names.index("delta")])
        fmu.doStep(t, ts)
        py.do_step(t, ts)
        plant.advance(to_ticks(t), to_ticks(ts),
                      {f"force[{j}]": b[names.index(f"force[{j}]")] for j in (1, 2, 3)})
    fmu.terminate()
    fmu.freeInstance()
    return {"bound": worst_bound, "diff": worst_diff, "events": events, "modes": modes,
            "rescued": count["qp_rescued"], "nodes": count["bnb_nodes"]}


@pytest.mark.parametrize(("ident", "stop", "overrides"), [
    ("Gmpc3", 30.0, {}),
    # braking early: the schedule's mode change cuts MB-MPC's blocks (a split problem)
    ("MbMpc3", 40.0, {"brake_from": 25.0, "brake_until_speed": 6.0}),
    # delta left to the MIQP: DAQP's branch and bound decides the modes on both sides
    ("Gmpc3", 20.0, {"delta_mode": "optimise"}),
])
def test_native_hybrid_mpc_equals_python_sample_by_sample(natives, ident, stop, overrides):
    out = lockstep(natives, ident, stop, overrides)
    assert out["diff"] <= out["bound"]
    if "brake_from" in overrides:
        assert out["modes"] == {0.0, 1.0}  # both modes applied within the run


@pytest.mark.slow
@pytest.mark.parametrize("ident", IDENTS)
def test_whole_shipped_run_native_hybrid_mpc_equals_python_sample_by_sample(natives, ident):
    sc = load_scenario(SCENARIO[ident])
    lockstep(natives, ident, sc.simulation.stop_time, {})


def _loop_bound(natives, ident: str, stop: float) -> float:
    return lockstep(natives, ident, stop, {})["bound"]


@pytest.mark.parametrize("ident", ["Gmpc3", pytest.param("MbMpc3", marks=pytest.mark.slow)])
def test_shipped_loop_with_native_hybrid_mpc_equals_python(natives, ident):
    from tests.test_native_controllers import SHORT_S, _compare

    _compare(SCENARIO[ident], ("controller",), SHORT_S, _loop_bound(natives, ident, SHORT_S))


@pytest.mark.parametrize("ident", IDENTS)
def test_native_hybrid_mpc_runs_in_fmpy_with_defaults(natives, ident):
    from fmpy import simulate_fmu

    path = natives[ident][0]
    res = simulate_fmu(str(path), stop_time=20.0)
    assert res["time"][-1] == pytest.approx(20.0)
    assert np.all(np.isfinite(res["force_demand"]))


def _native_refusal(native, params: dict) -> list[str]:
    """The messages the native FMU logs (logging off) when ``params`` make it refuse
    fmi2ExitInitializationMode (asserted)."""
    from fmpy.fmi1 import FMICallException

    logged: list[str] = []
    fmu, _ = initialising(native, logged)
    set_by_type(fmu, native[1], params)
    with pytest.raises(FMICallException):
        fmu.exitInitializationMode()
    return logged


@pytest.mark.parametrize(("params", "message"), [
    ({"N": 5, "move_blocks": "3:4"}, "move_blocks = '3:4': positive lengths summing to N = 5"),
    ({"R": 0.0}, "R = 0.0, dR = 0.0: both >= 0 and one > 0"),
    ({"configuration": "crh3_8car"}, "configuration = 'crh3_8car' has 8 cars, this "
     "controller has 3"),
    ({"position_reference": "map"}, "position_reference = 'map': must be one of 'horizon', "
     "'timetable'"),
    ({"delta_mode": "free"}, "delta_mode = 'free': must be one of 'schedule', 'optimise'"),
])
def test_bad_parameters_are_refused_by_both(natives, params, message):
    logged = _native_refusal(natives["Gmpc3"], params)
    assert any(message in text for text in logged), logged
    py = catalog()["Gmpc3"].load()(instance_name="python", resources=tempfile.mkdtemp())
    vr = {v.name: v for v in natives["Gmpc3"][1].modelVariables}
    for name, value in params.items():
        kind = {"Integer": "integer", "String": "string"}.get(vr[name].type, "real")
        getattr(py, f"set_{kind}")([vr[name].valueReference], [value])
    py.setup_experiment(0.0)
    py.enter_initialization_mode()
    with pytest.raises(ValueError, match=re.escape(message)):
        py.exit_initialization_mode()


def test_native_refuses_a_control_model_it_was_not_built_for(natives):
    """The zero-order hold and the PWA fit are build-time data: another sample time is
    refused by the native FMU with a message (the Python FMU computes its own)."""
    logged = _native_refusal(natives["Gmpc3"], {"sample_time": 0.5})
    assert any("sample_time = 0.5: the native FMU's control model is built for "
               "sample_time = 1.0" in text for text in logged), logged


def test_native_hybrid_state_is_complete(natives):
    """Get the FMU state mid-run, run on, restore it (and a serialized copy in a fresh
    instance): the same outputs again (the plan, the braking flag and the counters are state)."""
    sc = load_scenario(SCENARIO["MbMpc3"])
    params = {**sc.components["controller"].parameters, "brake_from": 8.0,
              "brake_until_speed": 1.0}
    md, fmu, _ = _instances(natives, "MbMpc3", params)
    inputs = [v.valueReference for v in md.modelVariables if v.causality == "input"]
    outputs = [v.valueReference for v in md.modelVariables
               if v.causality == "output" and v.type == "Real"]
    plant = Emu(emu_config("crh3_3car"), load_route("seed004_level"))
    names = [v.name for v in md.modelVariables if v.causality == "input"]
    log = []
    for k in range(14):
        o = plant.outputs()
        log.append([float(o[n]) for n in names])
        plant.advance(to_ticks(k), to_ticks(1.0), {f"force[{j}]": 1e4 for j in (1, 2, 3)})

    def run(slave, start: int) -> list:
        out = []
        for k in range(start, len(log)):
            slave.setReal(inputs, log[k])
            out.append(slave.getReal(outputs))
            slave.doStep(float(k), 1.0)
        return out

    for k in range(6):
        fmu.setReal(inputs, log[k])
        fmu.doStep(float(k), 1.0)
    state = fmu.getFMUstate()
    blob = fmu.serializeFMUstate(state)
    first = run(fmu, 6)
    fmu.setFMUstate(state)
    assert run(fmu, 6) == first
    _, md2, unzipdir = natives["MbMpc3"]
    other = FMU2Slave(guid=md2.guid, unzipDirectory=unzipdir, instanceName="other",
                      modelIdentifier="MbMpc3")
    other.instantiate()
    other.setFMUstate(other.deSerializeFMUstate(blob))
    assert run(other, 6) == first
    fmu.freeFMUstate(state)

