"""Speed-tracking PID core: closed-loop behaviour on analytic plants, saturation, error paths."""

from __future__ import annotations

import math

import pytest

from controllers.pid.speed_pid import SpeedPid, SpeedPidParams

EPS = 2.0**-52  # double precision machine epsilon


def test_proportional_loop_on_integrator_decays_geometrically() -> None:
    """Plant dv/dt = a (ZOH, sample T): e(k+1) = (1 - kp T) e(k) exactly with ki = kd = 0."""
    T, kp = 0.2, 1.5
    pid = SpeedPid(SpeedPidParams(kp=kp, ki=0.0, sample_time=T, accel_min=-10, accel_max=10))
    v, v_ref = 10.0, 12.0
    errors = []
    for _ in range(10):
        a = pid.update(v, v_ref)
        errors.append(v_ref - v)
        v += a * T
    # each sample rounds a handful of operations (error, P term, a T, v + a T) on values <=
    # v_ref: k samples leave at most 8 k ulps of v_ref, however small e has become
    for k, e in enumerate(errors):
        assert e == pytest.approx(2.0 * (1 - kp * T) ** k, abs=8 * k * EPS * v_ref)


def test_feedforward_tracks_a_ramp_without_error() -> None:
    """On a reference ramp v_ref = a0 t the feedforward alone keeps the error at zero."""
    T, a0 = 0.5, 0.4
    pid = SpeedPid(SpeedPidParams(kp=0.8, ki=0.1, sample_time=T))
    v = 0.0
    for k in range(100):
        a = pid.update(v, a0 * k * T, a_ref=a0)
        v += a * T
        # feedforward + PI terms and v + a T: <= 8 roundings of values <= v per sample
        assert abs(a0 * (k + 1) * T - v) <= 8 * (k + 1) * EPS * max(v, 1.0)


def test_integral_removes_constant_disturbance() -> None:
    """A constant unknown deceleration d: PI drives the steady-state error to zero."""
    T, d = 0.2, 0.15
    pid = SpeedPid(SpeedPidParams(kp=0.6, ki=0.1, sample_time=T))
    v = 50.0
    for _ in range(2000):
        a = pid.update(v, 50.0)
        v += (a - d) * T
    assert v == pytest.approx(50.0, abs=1e-6)
    assert pid.demand == pytest.approx(d, abs=1e-6)
    # P alone keeps an offset d / kp
    pid = SpeedPid(SpeedPidParams(kp=0.6, ki=0.0, sample_time=T))
    v = 50.0
    for _ in range(2000):
        v += (pid.update(v, 50.0) - d) * T
    assert 50.0 - v == pytest.approx(d / 0.6, rel=1e-6)


def test_saturation_and_antiwindup_limit_overshoot() -> None:
    """Large step: the demand stays in its limits and the frozen integral stops overshoot."""
    T = 0.2
    params = SpeedPidParams(kp=0.5, ki=0.2, sample_time=T, accel_min=-0.5, accel_max=0.5)
    pid = SpeedPid(params)
    v, peak = 0.0, 0.0
    for _ in range(3000):
        a = pid.update(v, 30.0)
        assert -0.5 <= a <= 0.5
        v += a * T
        peak = max(peak, v)
    # the integral only grows once the demand leaves saturation: overshoot stays small
    assert peak - 30.0 < 1.0
    assert v == pytest.approx(30.0, abs=1e-3)


def test_actuator_limits_passed_per_sample_are_honoured() -> None:
    pid = SpeedPid(SpeedPidParams(kp=5.0, ki=0.0))
    assert pid.update(0.0, 10.0, a_hi=0.3) == pytest.approx(0.3)
    assert pid.update(20.0, 10.0, a_lo=-0.2) == pytest.approx(-0.2)


def test_rate_limit_bounds_the_jerk() -> None:
    T, jerk = 0.2, 0.5
    pid = SpeedPid(SpeedPidParams(kp=5.0, ki=0.0, sample_time=T, rate_limit=jerk))
    demands = [pid.update(0.0, 10.0) for _ in range(20)]
    steps = [b - a for a, b in zip([0.0, *demands[:-1]], demands, strict=True)]
    # a step of the demand is clipped to jerk T and then rounded once (demands <= accel_max)
    assert max(abs(s) for s in steps) <= jerk * T + 2 * EPS * max(map(abs, demands))
    assert demands[-1] == pytest.approx(1.0)  # reached accel_max


def test_derivative_on_measurement_damps_without_kick() -> None:
    """A reference step gives no derivative kick; the D term opposes measured acceleration."""
    pid = SpeedPid(SpeedPidParams(kp=0.0, ki=0.0, kd=0.5, feedforward=False))
    assert pid.update(10.0, 10.0) == 0.0
    assert pid.update(10.0, 15.0) == 0.0  # reference step: no kick
    a = pid.update(10.2, 15.0)  # measured acceleration 1 m/s^2
    assert a == pytest.approx(-0.5)


def test_state_round_trip_reproduces_outputs() -> None:
    pid = SpeedPid(SpeedPidParams())
    for k in range(5):
        pid.update(10.0 + 0.1 * k, 12.0)
    state = pid.get_state()
    a = [pid.update(11.0, 12.0) for _ in range(3)]
    pid.set_state(state)
    assert [pid.update(11.0, 12.0) for _ in range(3)] == a


@pytest.mark.parametrize("field, value", [("sample_time", 0.0), ("kp", -1.0),
                                           ("ki", math.nan), ("accel_min", 2.0)])
def test_bad_parameters_are_rejected(field: str, value: float) -> None:
    with pytest.raises(ValueError, match=field):
        SpeedPid(SpeedPidParams(**{field: value}))


# -- distributed EMU controller ------------------------------------------------------------------
def _distributed(units: int = 3, **pid):
    import numpy as np

    from controllers.pid.speed_pid import DistributedSpeedPid, DistributedSpeedPidParams
    from plants.route import ReferenceProfile

    profile = ReferenceProfile("time", np.array([0.0, 100.0, 200.0]),
                               np.array([0.0, 40.0, 40.0]))
    params = DistributedSpeedPidParams(pid=SpeedPidParams(**pid), units=units, mass=1.5e5)
    return DistributedSpeedPid(params, profile)


def _limits(trac, brake):
    out = {f"traction_limit[{i + 1}]": t for i, t in enumerate(trac)}
    out.update({f"brake_limit[{i + 1}]": b for i, b in enumerate(brake)})
    return out


def test_force_is_shared_by_available_force() -> None:
    ctl = _distributed()
    inputs = {"v": 1.0, "s": 0.0, **_limits([6e4, 0.0, 3e4], [5e4, 5e4, 1e5])}
    out, hold = ctl.compute(10.0, inputs)  # too slow: traction
    assert hold == 1
    forces = [out[f"force[{i}]"] for i in (1, 2, 3)]
    assert forces[1] == 0.0  # the trailer never pulls
    assert forces[0] == pytest.approx(2 * forces[2])
    assert sum(forces) == pytest.approx(out["force_demand"])
    assert out["force_demand"] == pytest.approx(1.5e5 * out["accel_demand"])
    out, _ = ctl.compute(10.2, {**inputs, "v": 20.0})  # too fast: braking on every unit
    forces = [out[f"force[{i}]"] for i in (1, 2, 3)]
    assert all(f < 0 for f in forces)
    assert forces[2] == pytest.approx(2 * forces[0]) and forces[0] == pytest.approx(forces[1])


def test_demand_is_bounded_by_what_the_units_can_give() -> None:
    ctl = _distributed(kp=10.0)
    out, _ = ctl.compute(50.0, {"v": 0.0, "s": 0.0, **_limits([1e4, 0.0, 1e4], [1e5] * 3)})
    assert out["force_demand"] == pytest.approx(2e4)
    assert out["force[1]"] == pytest.approx(1e4)


def test_holds_the_brake_at_the_end_of_the_profile() -> None:
    import numpy as np

    from controllers.pid.speed_pid import DistributedSpeedPid, DistributedSpeedPidParams
    from plants.route import ReferenceProfile

    profile = ReferenceProfile("distance", np.array([0.0, 400.0]), np.array([20.0, 0.0]))
    ctl = DistributedSpeedPid(DistributedSpeedPidParams(pid=SpeedPidParams(), units=2,
                                                        mass=1e5, hold_accel=-0.4), profile)
    out, _ = ctl.compute(0.0, {"v": 0.1, "s": 400.2, **_limits([1e4, 1e4], [1e5, 1e5])})
    assert out["accel_demand"] == pytest.approx(-0.4)
    assert out["force[1]"] + out["force[2]"] == pytest.approx(-4e4)


@pytest.mark.parametrize("configuration", ["crh3_3car", "crh3_8car"])
def test_closed_loop_on_the_emu_core_meets_ctcs3(configuration: str) -> None:
    """PID + Emu core (CRH3, seed 004 reference) without FMUs: CTCS-3 at every sample."""
    import numpy as np

    from controllers.pid.speed_pid import DistributedSpeedPid, DistributedSpeedPidParams
    from cosim.fmu.state import to_ticks
    from plants.emu import Emu, emu_config
    from plants.route import load_route

    route = load_route("seed004_level")
    params = emu_config(configuration)
    emu = Emu(params, route)
    T = 1.0
    ctl = DistributedSpeedPid(DistributedSpeedPidParams(
        pid=SpeedPidParams(kp=0.5, ki=0.05, sample_time=T), units=params.n,
        mass=sum(params.masses)), route.reference)
    errors, refs = [], []
    for k in range(800):
        meas = emu.outputs()
        out, _ = ctl.compute(k * T, meas)
        errors.append(meas["v"] - out["v_ref"])
        refs.append(out["v_ref"])
        emu.advance(to_ticks(k * T), to_ticks(T), out)
    err_kmh, ref_kmh = np.abs(errors) * 3.6, np.array(refs) * 3.6
    allowed = np.where(ref_kmh <= 30.0, 2.0, 0.02 * ref_kmh)
    assert np.all(err_kmh <= allowed)
    assert err_kmh[250:].max() < 0.2  # after the transients of the start
