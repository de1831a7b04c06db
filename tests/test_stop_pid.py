"""Seed 000 PID baseline: the full-brake rule at the stop point is a parameter; without it the
default gains creep past the point, the retuned gains of ``seed000_stop_pid_plain`` stop inside
the +-0.5 m window on their own."""

from __future__ import annotations

from dataclasses import replace

import pytest

from controllers.pid.stop_pid import StopPid, StopPidParams
from cosim.fmu.state import to_ticks
from plants.brake_delay import BrakeDelayParams, BrakeDelayTrain
from plants.route import load_route

PLAIN = {"hold_at_stop_point": False, "kp": 80.0, "ki": 10.0, "kd": 15.0}  # the scenario's


def run(params: StopPidParams, stop_time: float = 60.0) -> tuple[float, float, list[float]]:
    """(stop error m, final speed m/s, commands) of the PID on the Table 1 plant."""
    plant = BrakeDelayTrain(BrakeDelayParams(), load_route("seed000_stop"), v0=20.0)
    core, T, commands = StopPid(params), params.sample_time, []
    for k in range(int(round(stop_time / T))):
        y = plant.outputs()
        u = core.compute(k * T, {"v": y["v"], "s": y["s"]})[0]["brake_command"]
        commands.append(u)
        plant.advance(to_ticks(k * T), to_ticks(T), {"brake_command": u})
    y = plant.outputs()
    return y["s"] - 400.0, y["v"], commands


def test_hold_rule_stops_the_default_pid():
    error, v, commands = run(StopPidParams())
    assert abs(error) <= 0.5 and v == 0.0
    assert commands[-1] > 50.0  # the rule's full-brake feedforward (less the integral) holds it


def test_default_gains_without_the_rule_creep_past_the_point():
    error, v, commands = run(replace(StopPidParams(), hold_at_stop_point=False))
    assert error > 0.5 and v > 0.0  # still moving at t = 60 s
    assert max(commands) < 100.0


def test_plain_pid_with_retuned_gains_stops_inside_the_window():
    error, v, commands = run(replace(StopPidParams(), **PLAIN))
    assert abs(error) <= 0.10 and v == 0.0
    assert all(0.0 <= u <= 100.0 for u in commands)


@pytest.mark.parametrize("kd", [10.0, 20.0])
def test_plain_pid_tuning_is_not_a_knife_edge(kd):
    """Neighbouring derivative gains still stop inside the window."""
    error, v, _ = run(replace(StopPidParams(), **{**PLAIN, "kd": kd}))
    assert abs(error) <= 0.5 and v == 0.0


def test_resistance_feedforward_is_the_mpcs_known_resistance():
    """resistance_feedforward: u_ff = (a0 - a_r(v, s)) / c with a_r the ideal MPC's known
    resistance (Davis / mass + the route's grade) at the same speed and position: the first
    command of the two PIDs differs by exactly -a_r / c."""
    from controllers.mpc.stop_mpc import IdealStopMpc, StopMpcParams

    base = replace(StopPidParams(), **PLAIN)
    fed = StopPid(replace(base, resistance_feedforward=True))
    plain = StopPid(base)
    mpc = IdealStopMpc(StopMpcParams())
    s = 200.0  # on the 28 permille grade, on the curve: no error, the feedforward alone
    v = (2.0 * base.ref_decel * (base.stop_point - s)) ** 0.5
    u_fed = fed.compute(0.0, {"v": v, "s": s})[0]["brake_command"]
    u_plain = plain.compute(0.0, {"v": v, "s": s})[0]["brake_command"]
    a_r = mpc.resistance(v, s)
    assert a_r > 0.2  # mostly the grade
    assert u_fed - u_plain == pytest.approx(-a_r / base.brake_gain, rel=1e-12)
