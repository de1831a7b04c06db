"""The native seed 000 predictive stopping controllers (cosim/fmu/native/controllers/stop_mpc.c
with DAQP built from its sdist) against their Python cores (controllers/mpc/stop_mpc.py).

Sample by sample: the native FMU and the Python FMU get the same FMI calls with the inputs of
the Python closed loop of each shipped seed 000 scenario (and the reproduction's variants:
W = whole resistance, disturbance observer), and every output is compared at every sample.
The counters, holds and announced next event times must be equal; the brake command may
differ by what the two builds' rounding and DAQP's tolerance allow:

* both builds solve the same QP, with data (Hessian, linear term, bounds) formed by sums of
  at most ``m`` products in different orders, so each data entry differs by at most
  ``2 gamma_m`` of the sum of the magnitudes; for one active set the solution is that of the
  KKT system ``K z = r`` (``K`` of the Hessian and the active rows, ``z`` = moves and active
  duals), whose relative change is at most ``cond(K)`` times the data's; DAQP stops when every
  inactive row is within ``primal_tol`` of its bound, so the two builds may take an active set
  that differs by such a row: the right-hand side moves by at most ``primal_tol``, the solution
  by ``||K^-1|| primal_tol``. ``K`` is formed at each event from the Python core's own QP and
  duals (its active set).
* an event's difference enters the next events through the command history; the bound of an
  event adds the bounds of the events before it (linear accumulation, no contraction assumed).

The closed loops of seed 000 (native controller with the Python plant and with the native
BrakeDelayTrain) are compared with the Python loop on the claims' metrics: the stop error
within ``n_events`` times the largest per-event command bound times the plant's position
response to a command step over the run (``c t^2 / 2``), the discrete metrics equal.
"""

from __future__ import annotations

import shutil
import tempfile

import numpy as np
import pytest
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave

from controllers.mpc.stop_mpc import StopMpcParams
from cosim.build.native import build_all_natives
from cosim.build.python import catalog
from cosim.fmu.declare import build
from cosim.fmu.state import to_ticks
from cosim.run.scenario import load_scenario
from cosim.run.simulate import run_scenario
from plants.brake_delay import BrakeDelayParams, BrakeDelayTrain
from plants.route import load_route

MPC = ("StopMpc", "StopRmpc", "StopRsmpc")
UNIT = 2.0**-53
PRIMAL_TOL = 1e-6  # DAQP's default primal_tol (HorizonQP keeps it)

# scenario, overrides: the shipped scenarios and the reproduction's variants of the tube MPCs
CASES = [
    ("seed000_stop_mpc", []),
    ("seed000_stop_mpc_euler", []),
    ("seed000_stop_mpc", ["controller.N=7", "controller.q_speed=3.0", "controller.r_du=0.05"]),
    ("seed000_stop_rmpc", []),
    ("seed000_stop_rsmpc", []),
    ("seed000_stop_rmpc", ["controller.N=5"]),
    ("seed000_stop_rsmpc", ["controller.N=5"]),
    ("seed000_stop_rmpc", ["controller.nominal_resistance=false"]),
    ("seed000_stop_rsmpc", ["controller.nominal_resistance=false"]),
    ("seed000_stop_rmpc", ["controller.disturbance_observer=true",
                           "controller.grade_uncertainty=0.1"]),
]


def gamma(n: int) -> float:
    return n * UNIT / (1 - n * UNIT)


@pytest.fixture(scope="module")
def natives(tmp_path_factory):
    if shutil.which("gcc") is None:
        pytest.skip("gcc not installed: native FMUs cannot be built")
    dest = tmp_path_factory.mktemp("native")
    built = build_all_natives(list(MPC), (2,), dest=dest, windows=False, workers=2)
    out = {}
    for ident, (path,) in built.items():
        md = read_model_description(str(path), validate=True)
        out[ident] = (path, md, extract(str(path), unzipdir=str(tmp_path_factory.mktemp(ident))))
    return out


class Pair:
    """A native and a Python instance of one controller, given the same FMI calls."""

    def __init__(self, natives, ident: str, params: dict) -> None:
        _, md, unzipdir = natives[ident]
        self.vars = {v.name: v for v in md.modelVariables}
        self.outputs = [v for v in md.modelVariables if v.causality == "output"]
        self.native = FMU2Slave(guid=md.guid, unzipDirectory=unzipdir, instanceName="native",
                                modelIdentifier=ident)
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
        kind = {"Real": "real", "Integer": "integer", "Boolean": "boolean",
                "String": "string"}[var.type]
        getattr(self.native, f"set{kind.capitalize()}")([var.valueReference], [value])
        getattr(self.py, f"set_{kind}")([var.valueReference], [value])

    def read(self) -> tuple[dict, dict]:
        native, py = {}, {}
        for v in self.outputs:
            vr = [v.valueReference]
            if v.type == "Real":
                native[v.name], py[v.name] = self.native.getReal(vr)[0], self.py.get_real(vr)[0]
            else:
                native[v.name] = self.native.getInteger(vr)[0]
                py[v.name] = self.py.get_integer(vr)[0]
        return native, py


def event_bound(core) -> float:
    """The bound of one event's command (module docstring) from the Python core's QP of the
    command it took: its hold's QP (the fallback's when the tightened one was infeasible)."""
    hold = core.hold
    key = hold if hold in core.warm else 0
    if key not in core.warm:  # no QP answer taken: the clipped tube law (4 products)
        return gamma(8) * (1.0 + float(np.abs(core.K).sum()) * 1e3)
    qp = core.qp(key) if key > 0 else core.fallback_qp()
    U, dual = (np.asarray(x, float) for x in core.warm[key])
    active = np.flatnonzero(dual != 0.0)
    Hd = 2.0 * qp.Hhalf
    A = qp.Acon[active]
    n, k = Hd.shape[0], len(active)
    K = np.block([[Hd, A.T], [A, np.zeros((k, k))]])
    z = np.concatenate([U, dual[active]])
    m = (qp.H + 1) * qp.n + qp.H + qp.n  # longest dot product of the vector update
    return float(np.linalg.cond(K) * 2.0 * gamma(m) * (1.0 + np.abs(z).max())
                 * (1.0 + np.abs(qp.Acon).sum(axis=1).max())
                 + np.abs(np.linalg.inv(K)).sum(axis=1)[:n].max() * PRIMAL_TOL)


COUNTERS = ("qp_solves", "qp_infeasible", "hold_steps", "qp_infeasible_after_stop",
            "events_moving", "events_standstill", "executions", "next_event_time")


@pytest.mark.parametrize(("name", "overrides"), CASES)
def test_native_mpc_equals_python_core_on_the_scenario_inputs(natives, name, overrides):
    sc = load_scenario(name, overrides)
    ctrl, plant_c = sc.components["controller"], sc.components["plant"]
    pair = Pair(natives, ctrl.fmu, ctrl.parameters)
    pv = plant_c.parameters
    plant = BrakeDelayTrain(build(BrakeDelayParams, pv), load_route(pv["route"]),
                            v0=pv["v0"], s0=pv["s0"])
    T = float(ctrl.sample_time)
    accumulated, worst, events = 0.0, 0.0, 0
    for k in range(int(round(sc.simulation.stop_time / T))):
        y = plant.outputs()
        for key in ("v", "s", "a_c"):
            pair.set(key, y[key])
        native, py = pair.read()
        where = f"{name} {overrides} at t = {k * T:.1f} s"
        assert {c: native[c] for c in COUNTERS} == {c: py[c] for c in COUNTERS}, where
        if py["executions"] > events:  # an event at this sample
            events = py["executions"]
            accumulated += event_bound(pair.py.core)
        for key in ("brake_command", "v_ref", "resistance_estimate"):
            a, b = native[key], py[key]
            tol = accumulated + 2 * UNIT * abs(b) if key == "brake_command" else \
                gamma(4) * abs(b) + (accumulated if key == "resistance_estimate" else 0.0)
            assert abs(a - b) <= tol, f"{where}: {key} native {a!r}, Python {b!r}, bound {tol}"
            worst = max(worst, abs(a - b))
        pair.native.doStep(k * T, T)
        pair.py.do_step(k * T, T)
        plant.advance(to_ticks(k * T), to_ticks(T), {"brake_command": py["brake_command"]})
    assert events > 20
    assert accumulated < 0.1  # meaningful: a tenth of a percent of brake command at most


def python_loop(name: str, offset: float = 0.0) -> tuple[float, float]:
    """The Python core's own closed loop of scenario ``name`` (plant core, controller core,
    no FMI), the plant given each command plus ``offset`` (%): the final position (m) and the
    accumulated command bound of its last event (:func:`event_bound`, summed as in
    :func:`test_native_mpc_equals_python_core_on_the_scenario_inputs`)."""
    sc = load_scenario(name)
    ctrl, pv = sc.components["controller"], sc.components["plant"].parameters
    core = catalog()[ctrl.fmu].load().core_class(build(StopMpcParams, ctrl.parameters))
    plant = BrakeDelayTrain(build(BrakeDelayParams, pv), load_route(pv["route"]),
                            v0=pv["v0"], s0=pv["s0"])
    T = float(ctrl.sample_time)
    accumulated, next_event, u = 0.0, 0, 0.0
    for k in range(int(round(sc.simulation.stop_time / T))):
        if k == next_event:
            y = plant.outputs()
            out, hold = core.compute(k * T, {"v": y["v"], "s": y["s"], "a_c": y["a_c"]})
            u, next_event = out["brake_command"], k + max(1, hold)
            accumulated += event_bound(core)
        plant.advance(to_ticks(k * T), to_ticks(T), {"brake_command": u + offset})
    return plant.outputs()["s"], accumulated


@pytest.mark.parametrize("name", ["seed000_stop_mpc", "seed000_stop_rmpc", "seed000_stop_rsmpc"])
@pytest.mark.parametrize("plant", [False, True], ids=["python_plant", "native_plant"])
def test_seed000_closed_loop_native_equals_python_on_the_claims_metrics(natives, name, plant):
    """The scenario run by the master with the native controller (and the native
    BrakeDelayTrain) against the Python run. The commands differ by at most the accumulated
    event bound B (module docstring); the stop error's response to such a difference is taken
    to first order from the Python core loop itself, run with every command offset by +B and
    -B: the stop errors may differ by twice the larger response (any sign pattern within B,
    first order) plus the rounding of two positions. The discrete metrics are equal."""
    py = run_scenario(name, [], plot=False)
    nat = run_scenario(name, ["controller.build=native"] + (["plant.build=native"] if plant
                                                             else []), plot=False)
    s0, bound = python_loop(name)
    response = max(abs(python_loop(name, sign * bound)[0] - s0) for sign in (1.0, -1.0))
    stop_bound = 2.0 * response + 4 * UNIT * abs(s0)
    assert stop_bound < 0.01  # meaningful: below a centimetre (the claims are +-50 cm)
    a, b = py.summary["stop_error_m"], nat.summary["stop_error_m"]
    assert abs(a - b) <= stop_bound, (a, b, stop_bound)
    for key in ("command_switches", "qp_infeasible", "events_moving", "qp_solves"):
        if key in py.summary:
            assert py.summary[key] == nat.summary[key], key


@pytest.mark.parametrize("ident", MPC)
def test_native_mpc_state_restores_the_same_run(natives, ident):
    """The FMU state (command history, plan, the kept duals of each hold, counters, observer)
    is complete: a run restored to a saved state repeats its outputs bit for bit, although
    the DAQP workspaces have solved other data in between."""
    _, md, unzipdir = natives[ident]
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzipdir, instanceName="state",
                    modelIdentifier=ident)
    fmu.instantiate()
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    vr = {v.name: v.valueReference for v in md.modelVariables}
    outputs = [v.valueReference for v in md.modelVariables
               if v.causality == "output" and v.type == "Real"]
    T = 0.2

    def run(k0: int, k1: int) -> list:
        rows = []
        for k in range(k0, k1):
            v = max(20.0 - 0.55 * k * T, 0.0)
            fmu.setReal([vr["v"], vr["s"], vr["a_c"]], [v, 20.0 * k * T - 0.27 * (k * T)**2,
                                                        -0.5])
            rows.append(fmu.getReal(outputs))
            fmu.doStep(k * T, T)
        return rows

    run(0, 40)
    saved = fmu.getFMUstate()
    first = run(40, 80)
    fmu.setFMUstate(saved)
    assert run(40, 80) == first
    fmu.freeFMUstate(saved)
    fmu.terminate()
    fmu.freeInstance()


@pytest.mark.parametrize(("ident", "params", "message"), [
    ("StopRmpc", {"mass_uncertainty": 0.05}, "no terminal set is shipped for this design"),
    ("StopRsmpc", {"position_error_max": 15.0}, "no terminal set is shipped for this design"),
    ("StopMpc", {"qp_solver": "osqp"}, "qp_solver = 'osqp': the native build solves with DAQP"),
    ("StopMpc", {"route": "/tmp/x.toml"}, "the native build reads bundled routes only"),
])
def test_native_mpc_refuses_what_it_has_no_data_for(natives, ident, params, message):
    """A tube design whose terminal set is not shipped, another QP solver, a route path: the
    initialisation fails with a message naming it (logged with logging off). The ideal MPC
    has no terminal set: another design of it is built in C and runs."""
    from fmpy.fmi1 import FMICallException
    from native_helpers import initialising, set_by_type

    messages: list[str] = []
    fmu, _ = initialising(natives[ident], messages)
    set_by_type(fmu, natives[ident][1], params)
    with pytest.raises(FMICallException):
        fmu.exitInitializationMode()
    assert any(message in m for m in messages), messages
    fmu.freeInstance()
    other, _ = initialising(natives["StopMpc"], None)
    set_by_type(other, natives["StopMpc"][1], {"N": 7, "q_speed": 3.0, "mass": 400e3})
    other.exitInitializationMode()
    other.doStep(0.0, 0.2)
    other.terminate()
    other.freeInstance()
