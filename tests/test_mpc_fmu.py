"""MPC FMUs under the master: summary targets, event-driven == fixed-step, RSMPC called once
per event, FMU state save/restore through FMI."""

from __future__ import annotations

import numpy as np
import pytest
from fmi_state_helpers import rerun_after_restore

from cosim.run.simulate import run_scenario

RSMPC = "seed000_stop_rsmpc"


@pytest.fixture(scope="module")
def rsmpc_event(built_fmus):
    return run_scenario(RSMPC, build=False, plot=False)


def _max_diff(a, b) -> float:
    fa, fb = a.frame.set_index("time"), b.frame.set_index("time")
    common = fa.index.intersection(fb.index)
    assert len(common) == len(fa)
    cols = [c for c in fa.columns if c in fb.columns]
    return float(np.max(np.abs(fa.loc[common, cols].to_numpy() - fb.loc[common, cols].to_numpy())))


def test_summary_has_qp_and_comfort_figures(rsmpc_event):
    s = rsmpc_event.summary
    for key in ("qp_solves", "qp_solve_time_median_s", "qp_infeasible", "max_jerk_mps3",
                "speed_rmse_mps", "stop_error_m", "command_switches"):
        assert key in s, key
    assert s["qp_solves"] >= s["executions"]["controller"] / 2  # none at standstill only
    assert s["qp_infeasible"] == 0
    assert 0.0 < s["qp_solve_time_median_s"] < 0.5
    assert abs(s["stop_error_m"]) <= 0.5


@pytest.mark.parametrize("base_step", [0.2, 0.05])
def test_rsmpc_event_driven_equals_fixed_step(rsmpc_event, base_step):
    fixed = run_scenario(RSMPC, algorithm="fixed", build=False, plot=False,
                         overrides={"simulation.base_step": base_step})
    assert _max_diff(rsmpc_event, fixed) < 1e-9
    # the fixed-step master steps the controller every base step; it computes only at events
    assert fixed.do_steps["controller"] == round(60.0 / base_step)
    assert fixed.executions["controller"] == rsmpc_event.executions["controller"]


def test_event_master_calls_rsmpc_once_per_event(rsmpc_event):
    """Event-driven: one doStep per event interval, as many events as the FMU computed, and
    the events are exactly the hold boundaries the FMU announced (t_{i+1} = t_i + M_i T)."""
    ex, steps = rsmpc_event.executions["controller"], rsmpc_event.do_steps["controller"]
    assert steps == ex - 1
    assert ex < 301 / 2  # self-triggered: far fewer than one per 0.2 s sample
    frame = rsmpc_event.frame
    u = frame["controller.brake_command"].to_numpy()
    hold = frame["controller.hold_steps"].to_numpy()
    t = frame["time"].to_numpy()
    # walk the announced events over the recorded 0.2 s grid: the command is constant
    # between them, and their number is the number of computations
    k, events = 0, 0
    while k <= len(t) - 1:
        m = int(hold[k])
        assert m >= 1
        assert np.all(u[k:k + m] == u[k])
        k, events = k + m, events + 1
    assert events == ex


@pytest.mark.parametrize("scenario,limit", [("seed000_stop_mpc", 0.10),
                                            ("seed000_stop_rmpc", 0.50)])
def test_scenarios_stop_inside_targets(built_fmus, scenario, limit):
    s = run_scenario(scenario, build=False, plot=False).summary
    assert abs(s["stop_error_m"]) <= limit
    assert s["final_speed_mps"] == 0.0
    assert s["qp_infeasible"] == 0


def test_rsmpc_at_n10_executes_at_most_half_of_rmpc(built_fmus, rsmpc_event):
    rmpc = run_scenario("seed000_stop_rmpc", build=False, plot=False,
                        overrides={"controller.N": 10})
    rs, rm = rsmpc_event.summary, rmpc.summary
    assert rs["executions"]["controller"] <= rm["executions"]["controller"] / 2
    assert rs["command_switches"] <= rm["command_switches"] / 2


def test_override_horizon_changes_the_run(built_fmus, rsmpc_event):
    short = run_scenario(RSMPC, build=False, plot=False, overrides={"controller.N": 3})
    assert short.executions["controller"] > rsmpc_event.executions["controller"]


def test_rsmpc_fmu_state_restore_reproduces_the_rest(built_fmus):
    """Serialize plant + RSMPC FMU state mid-run through FMI, finish, restore, rerun."""
    from test_fmus import Instance

    plant = Instance(built_fmus["BrakeDelayTrain"].path, "plant")
    ctrl = Instance(built_fmus["StopRsmpc"].path, "rsmpc")
    h = 0.2

    def step(k: int) -> tuple[float, float, float]:
        for name in ("v", "s", "a_c"):
            ctrl.set(name, plant.get(name))
        u = ctrl.get("brake_command")
        plant.set("brake_command", u)
        plant.fmu.doStep(currentCommunicationPoint=k * h, communicationStepSize=h)
        ctrl.fmu.doStep(currentCommunicationPoint=k * h, communicationStepSize=h)
        return plant.get("v"), plant.get("s"), u

    first, again = rerun_after_restore([plant, ctrl], step, 60, 160)
    assert first == again
    assert len({u for _, _, u in first}) > 3
    for inst in (plant, ctrl):
        inst.fmu.terminate()
        inst.fmu.freeInstance()
