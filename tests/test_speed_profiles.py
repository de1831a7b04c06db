"""Seed 003 target profiles (controllers/common/speed_profiles.py): limits, the eco switching
rule, arrival within the running-time margin, phases."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from controllers.common import speed_profiles as sp
from cosim.run.scenario import load_scenario
from plants.crh3 import Crh3Params
from plants.resistance import KMH
from plants.route import Route, StepProfile, load_route

ROUTE = load_route("seed003_crh3")
DELTA_T_MAX = 5.0  # s, sec. 4


def test_conventional_accelerates_cruises_at_v_act_and_brakes() -> None:
    prof = sp.generate("conventional", ROUTE)
    st = sp.ProfileSettings()
    assert prof.v[0] == 0.0 and prof.v[-1] == 0.0 and prof.stop_point == ROUTE.length_m
    assert np.max(prof.v) == pytest.approx(st.cruise_speed, abs=1e-9)
    assert set(np.unique(prof.mode[:-1])) <= {sp.TRACTION, sp.CRUISE, sp.BRAKE}
    assert np.all(np.abs(prof.accel) <= 1.0 + 1e-12)
    braking = prof.mode[:-1] == sp.BRAKE
    assert np.allclose(prof.accel[:-1][braking], -st.brake_decel, rtol=1e-9)
    # the shortest run: the time the timetable's supplement is added to
    assert prof.arrival_time < ROUTE.scheduled_time_s


def test_eco_meets_the_scheduled_time_within_the_margin() -> None:
    eco = sp.generate("eco", ROUTE)
    st = sp.ProfileSettings()
    assert abs(eco.arrival_time - ROUTE.scheduled_time_s) <= st.time_tolerance
    assert st.time_tolerance < DELTA_T_MAX
    modes = set(np.unique(eco.mode[:-1]))
    assert {sp.TRACTION, sp.COAST, sp.REACCELERATE, sp.BRAKE} <= modes
    assert sp.CRUISE not in modes
    assert np.max(eco.v) <= st.limit_speed + 1e-9 and np.all(np.abs(eco.accel) <= 1.0 + 1e-12)
    # the rule: re-acceleration starts where the coasting speed has fallen to V_low
    starts = np.nonzero((eco.mode[1:] == sp.REACCELERATE) & (eco.mode[:-1] == sp.COAST))[0] + 1
    assert starts.size >= 1
    assert np.all(eco.v[starts] <= eco.low_speed + 1e-9)
    assert np.all(eco.v[starts - 1] > eco.low_speed)


@pytest.mark.parametrize("scheduled", [1900.0, 2200.0])
def test_eco_arrival_follows_any_feasible_schedule(scheduled: float) -> None:
    eco = sp.generate("eco", ROUTE, scheduled)
    assert abs(eco.arrival_time - scheduled) <= sp.ProfileSettings().time_tolerance


def test_without_a_margin_eco_is_the_conventional_profile() -> None:
    conv = sp.generate("conventional", ROUTE)
    eco = sp.generate("eco", ROUTE, conv.arrival_time - 10.0)
    assert np.array_equal(eco.v, conv.v) and eco.arrival_time == conv.arrival_time


def test_eco_needs_less_mechanical_work_than_conventional() -> None:
    """Along the profiles, the traction work of the nominal model is smaller for eco."""
    conv, eco = (sp.generate(k, ROUTE) for k in ("conventional", "eco"))
    assert sp.traction_work(eco, ROUTE) < 0.9 * sp.traction_work(conv, ROUTE)


def test_traction_work_of_a_level_cruise_is_resistance_times_distance() -> None:
    """Analytic check: on level track at constant speed the work is Davis(v) x distance."""
    flat, p = Route.flat(8e4), Crh3Params()  # 33 km to reach V_act
    prof = sp.generate("conventional", flat)
    steps = np.flatnonzero((prof.mode[:-1] == sp.CRUISE) & (prof.accel[:-1] == 0.0))
    a, b = steps[1], steps[-1]  # interior steps at V_act (no entry/exit step)
    part = dataclasses.replace(prof, s=prof.s[a:b + 1], v=prof.v[a:b + 1], t=prof.t[a:b + 1],
                               mode=prof.mode[a:b + 1])
    v = sp.ProfileSettings().cruise_speed
    expected = p.davis.force(v) * (part.s[-1] - part.s[0])
    assert sp.traction_work(part, flat) == pytest.approx(expected, rel=1e-12)


@pytest.mark.parametrize("scheduled", [1900.0, 2100.0, 2200.0])
def test_cruise_meets_the_schedule_at_one_constant_speed(scheduled: float) -> None:
    """The same-schedule baseline: accelerate, cruise at V_c, brake; arrival within the
    profile tolerance; a later schedule gives a lower V_c."""
    st = sp.ProfileSettings()
    prof = sp.generate("cruise", ROUTE, scheduled)
    assert abs(prof.arrival_time - scheduled) <= st.time_tolerance
    assert set(np.unique(prof.mode[:-1])) <= {sp.TRACTION, sp.CRUISE, sp.BRAKE}
    assert np.max(prof.v) == pytest.approx(prof.low_speed, abs=1e-9)
    assert prof.low_speed < st.cruise_speed
    if scheduled > 1900.0:
        assert prof.low_speed < sp.generate("cruise", ROUTE, 1900.0).low_speed


def test_without_a_margin_cruise_is_the_conventional_profile() -> None:
    conv = sp.generate("conventional", ROUTE)
    cruise = sp.generate("cruise", ROUTE, conv.arrival_time - 10.0)
    assert np.array_equal(cruise.v, conv.v)


def test_lookups_by_time_and_position_agree() -> None:
    prof = sp.generate("eco", ROUTE)
    for t in (10.0, 400.0, 1000.0, 1500.0, 2050.0):
        s, v, _ = prof.at_time(t)
        v_s, _ = prof.at_position(s)
        # v linear in t inside a step but v^2 linear in s: they differ by O(a^2 dt^2 / v)
        assert v_s == pytest.approx(v, abs=1e-3)
    assert prof.at_time(-1.0)[1] == 0.0 and prof.at_time(1e5) == (ROUTE.length_m, 0.0, 0.0)
    assert prof.phase_at_time(1.0) == sp.PHASE_ACCELERATE
    assert prof.phase_at_time(prof.accelerate_end_time + 1.0) == sp.PHASE_RUN
    assert prof.phase_at_time(prof.arrival_time - 1.0) == sp.PHASE_BRAKE
    assert prof.accelerate_end_time < prof.brake_start_time


def test_a_down_grade_caps_coasting_at_v_lim() -> None:
    steep = Route("down", 60000.0, StepProfile.from_pairs([[0.0, 0.0], [25000.0, -20.0],
                                                          [45000.0, 0.0]]),
                  speed_limit=StepProfile.from_pairs([[0.0, 350.0 * KMH]]))
    st = sp.ProfileSettings()
    _, v, mode = sp._run(sp._Model(Crh3Params(), steep, st), steep.length_m, "eco",
                         300.0 * KMH)
    assert sp.HOLD_LIMIT in set(mode)
    assert np.max(v) == pytest.approx(st.limit_speed, abs=1e-9)
    # faster than the conventional run whatever V_low: such a schedule is refused, by name
    with pytest.raises(ValueError, match="'down': no eco profile arrives"):
        sp.generate("eco", steep, sp.generate("conventional", steep).arrival_time + 20.0)


def test_scenarios_plan_the_generated_arrival_times() -> None:
    # the fixed family plans the optimal rows' schedule (their scenario, profile overridden)
    for kind in sp.PROFILE_KINDS:
        stem = "optimal" if kind == "fixed_family" else kind
        sc = load_scenario(f"seed003_crh3_gpc_{stem}")
        planned = float(sc.summary["planned_arrival_time"])
        prof = sp.generate(kind, ROUTE)
        assert abs(prof.arrival_time - planned) <= sp.ProfileSettings().time_tolerance
        assert sc.summary["stop_point"] == prof.stop_point


def test_errors_name_the_problem() -> None:
    with pytest.raises(ValueError, match="profile 'fast'"):
        sp.generate("fast", ROUTE)
    with pytest.raises(ValueError, match="no scheduled_time_s"):
        sp.generate("eco", Route.flat(1e4))
    with pytest.raises(ValueError, match="no scheduled_time_s"):
        sp.generate("cruise", Route.flat(1e4))
    with pytest.raises(ValueError, match="before scheduled_time"):
        sp.generate("cruise", Route.flat(1e4), 1e5)
    with pytest.raises(ValueError, match="accel_max"):
        sp.generate("conventional", ROUTE,
                    settings=dataclasses.replace(sp.ProfileSettings(), accel_max=1.5))
    assert math.isfinite(sp.generate("conventional", Route.flat(1e4)).arrival_time)


def test_the_eco_search_is_kept_on_disk_and_gives_the_same_profile(tmp_path,
                                                                   monkeypatch) -> None:
    """The eco bisection's V_low is stored once per (route, schedule, train, settings); a later
    process (here: an emptied in-process cache) rebuilds the same profile from it."""
    monkeypatch.setenv("ATO_COSIM_CACHE", str(tmp_path))
    sp._CACHE.clear()
    first = sp.generate("eco", ROUTE)
    assert len(list((tmp_path / "designs").glob("eco_profile-*"))) == 1
    sp._CACHE.clear()
    again = sp.generate("eco", ROUTE)
    assert again is not first and again.low_speed == first.low_speed
    for name in ("s", "v", "t", "mode"):
        np.testing.assert_array_equal(getattr(again, name), getattr(first, name))
    sp._CACHE.clear()


def test_the_stopping_curve_over_an_array_is_its_speed_at_each_position() -> None:
    """StoppingCurve.speeds (the summary's reference over a recording) gives speed(s) bit for
    bit, before, at and past the stop point, and NaN where the position is NaN."""
    from cosim.fmu.profiles import StoppingCurve

    curve = StoppingCurve(0.47, 400.0)
    s = np.concatenate([np.linspace(-3.0, 400.0, 997), [399.999999999, 400.0, 400.5, 1e9,
                                                          np.nan]])
    got = curve.speeds(s)
    want = [curve.speed(x) for x in s]
    assert [v.hex() for v in got[:-1]] == [v.hex() for v in want[:-1]]
    assert math.isnan(got[-1]) and math.isnan(want[-1])
