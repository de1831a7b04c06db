"""Seed-000 brake-delay plant core against analytic solutions and invariants."""

from __future__ import annotations

import math

import numpy as np
import pytest

from cosim.fmu.state import to_ticks
from plants.brake_delay import BrakeDelayParams, BrakeDelayTrain
from plants.resistance import Davis
from plants.route import Route, load_route

EPS = np.finfo(float).eps

NO_DRAG = Davis(0.0, 0.0, 0.0)


def make(davis: Davis = NO_DRAG, route: Route | None = None, **kw) -> BrakeDelayTrain:
    params = BrakeDelayParams(davis=davis, **{k: kw.pop(k) for k in list(kw)
                                              if k in BrakeDelayParams.__dataclass_fields__})
    return BrakeDelayTrain(params, route or Route.flat(), **kw)


def run(train: BrakeDelayTrain, commands, step: float, stop: float) -> list[dict]:
    """Advance with ``commands(t)`` held over each communication step; outputs per step."""
    t, rows = 0, [train.outputs()]
    h = to_ticks(step)
    while t < to_ticks(stop) - 1:
        hh = min(h, to_ticks(stop) - t)
        train.advance(t, hh, {"brake_command": commands(t / 1e9)})
        t += hh
        rows.append({"t": t / 1e9, **train.outputs()})
    return rows


def test_lag_and_dead_time_step_response_is_exact():
    p = BrakeDelayParams()
    c, tau, td, u = p.brake_gain, p.brake_time_constant, p.brake_delay, 60.0
    train = make(v0=50.0)
    rows = run(train, lambda t: u, 0.1, 5.0)
    # each sub-step of the exact lag a' = e a + (1 - e) a_target rounds ~4 times values <= c u
    substeps = round(5.0 / p.max_step)
    a_tol = 4 * substeps * EPS * c * u
    for row in rows[1:]:
        t = row["t"]
        tt = max(t - td, 0.0)
        a_c = -c * u * (1.0 - math.exp(-tt / tau))
        v = 50.0 - c * u * (tt - tau * (1.0 - math.exp(-tt / tau)))
        assert row["a_c"] == pytest.approx(a_c, abs=a_tol)
        assert row["v"] == pytest.approx(v, abs=1e-9)


@pytest.mark.parametrize("step", [0.37, 0.2, 0.013])
def test_dead_time_exact_for_any_step(step):
    """A command set at t0 has no effect before t0 + Td and acts right after."""
    td = BrakeDelayParams().brake_delay
    t_cmd = 3 * step
    train = make(v0=30.0)
    t, h = 0, to_ticks(step)
    seen_before, seen_after = [], []
    while t < to_ticks(t_cmd + td + 1.0):
        u = 80.0 if t >= to_ticks(t_cmd) else 0.0
        train.advance(t, h, {"brake_command": u})
        t += h
        (seen_before if t <= to_ticks(t_cmd + td) else seen_after).append(train.outputs())
    assert all(o["a_c"] == 0.0 for o in seen_before)
    assert all(o["applied_command"] == 0.0 for o in seen_before[:-1])
    assert all(o["a_c"] < 0.0 and o["applied_command"] == 80.0 for o in seen_after)


def test_constant_deceleration_stopping_distance():
    """Brake in equilibrium from the start, no resistance: s = v0^2 / (2 a), then at rest."""
    u0 = 50.0
    decel = BrakeDelayParams().brake_gain * u0
    train = make(v0=20.0, initial_command=u0)
    rows = run(train, lambda t: u0, 0.2, 60.0)
    assert rows[-1]["v"] == 0.0
    assert rows[-1]["s"] == pytest.approx(20.0**2 / (2 * decel), abs=1e-6)
    stop_time = 20.0 / decel
    moving = [r for r in rows[1:] if r["v"] > 0]
    assert moving[-1]["t"] <= stop_time + 1e-9


def test_no_rollback_on_uphill_at_rest():
    route = load_route("seed000_stop")  # 12 permille uphill at the start
    train = make(v0=0.0, route=route)
    rows = run(train, lambda t: 0.0, 0.5, 10.0)
    assert all(r["v"] == 0.0 and r["s"] == 0.0 for r in rows)


def _final_state(step: float, max_step: float = 0.01) -> np.ndarray:
    """Command changes every 0.2 s (a sampled controller); communication steps of ``step``
    inside each 0.2 s window, the last one shortened to end on the window."""
    route = load_route("seed000_stop")
    train = make(davis=Davis.from_kn_kmh(5.4, 0.0098, 0.00163), route=route, v0=20.0,
                 max_step=max_step)
    window, h = to_ticks(0.2), to_ticks(step)
    t = 0
    for k in range(150):
        u = 40.0 + 10.0 * math.sin(k)
        end = (k + 1) * window
        while t < end:
            hh = min(h, end - t)
            train.advance(t, hh, {"brake_command": u})
            t += hh
    out = train.outputs()
    return np.array([out["v"], out["s"], out["a_c"]])


def test_step_size_independence_on_grid():
    """Communication steps on the max_step grid give the same trajectory to rounding."""
    ref = _final_state(0.2)
    for step in (0.1, 0.05, 0.01):
        assert np.max(np.abs(_final_state(step) - ref)) < 1e-9


def test_step_size_independence_off_grid_and_convergence():
    ref = _final_state(0.2)
    assert np.max(np.abs(_final_state(0.013) - ref)) < 1e-8
    fine = _final_state(0.2, max_step=0.0025)
    assert np.max(np.abs(fine - ref)) < 1e-6


def test_state_save_restore_reproduces_rest_of_run():
    route = load_route("seed000_stop")
    train = make(route=route, v0=20.0)
    h = to_ticks(0.2)
    for k in range(20):
        train.advance(k * h, h, {"brake_command": 5.0 * k})
    saved = train.get_state()
    tail = []
    for k in range(20, 40):
        train.advance(k * h, h, {"brake_command": 100.0 - k})
        tail.append(train.outputs())
    train.set_state(saved)
    for k in range(20, 40):
        train.advance(k * h, h, {"brake_command": 100.0 - k})
        assert train.outputs() == tail[k - 20]


def test_bad_parameters_rejected():
    with pytest.raises(ValueError, match="brake_time_constant"):
        make(v0=1.0, brake_time_constant=0.0)
    with pytest.raises(ValueError, match="v0"):
        make(v0=-1.0)
    with pytest.raises(ValueError, match="not found"):
        load_route("no_such_route")


def test_disturbance_is_a_seeded_bounded_piecewise_constant_resistance() -> None:
    """a_d: uniform in [-A, A], constant over each disturbance_interval, a function of the
    time and the seed only; with the brake released on a level route the speed difference of
    two runs, without and with it, is the integral of a_d within the bound the Davis force's
    speed dependence allows."""
    from dataclasses import replace

    from plants.brake_delay import BrakeDelayParams, BrakeDelayTrain
    from plants.route import Route

    p = replace(BrakeDelayParams(), disturbance_amplitude=0.02, disturbance_seed=3,
                disturbance_interval=1.0)
    plant = BrakeDelayTrain(p, Route.flat(), v0=20.0)
    values = [plant.disturbance_at(0.2 * k) for k in range(50)]
    assert all(abs(x) <= 0.02 for x in values)
    assert len(set(values[0:5])) == 1 and values[5] != values[4]
    again = BrakeDelayTrain(p, Route.flat(), v0=20.0)
    assert [again.disturbance_at(0.2 * k) for k in range(49, -1, -1)] == values[::-1]
    free = BrakeDelayTrain(replace(p, disturbance_amplitude=0.0), Route.flat(), v0=20.0)
    for k in range(50):
        for train in (plant, free):
            train.advance(to_ticks(0.2 * k), to_ticks(0.2), {"brake_command": 0.0})
    # d(gap)/dt = a_d + (Davis(v_p) - Davis(v_f)) / m with gap = v_f - v_p: the second term
    # is at most slope |gap| <= slope A t (slope of Davis / m at the top speed, 20 m/s), so
    # |gap - int a_d| <= slope A t^2 over the t = 10 s
    gap = free.v - plant.v
    integral = 0.2 * sum(values)
    slope = (p.davis.b + 2.0 * p.davis.c * 20.0) / p.mass
    bound = slope * 0.02 * 10.0**2
    assert abs(integral) > 3 * bound  # the seed's disturbance is visible against the bound
    assert abs(gap - integral) <= bound
