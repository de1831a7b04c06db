"""Shared traction / electric brake / air brake blending of the freight controllers (seed 002)."""

from __future__ import annotations

import numpy as np
import pytest

from controllers.common.freight_blending import BlendingParams, FreightBlending
from controllers.pid.freight_pid import FreightPid, FreightPidParams
from plants.freight import FreightTrain, friction_coefficient_at
from plants.route import ReferenceProfile, Route, load_route
from tests.freight_loop import closed_loop


def _constant_decel_reference(route: Route, cruise: float = 69.2 / 3.6,
                              decel: float = 0.2) -> ReferenceProfile:
    """Cruise, then a constant ``decel`` (m/s^2) to the end of ``route``: the final braking
    of the first freight_20km reference, not planned with the air brake (issue 16)."""
    end = route.length_m
    s = np.arange(0.0, end + 5.0, 10.0)
    v = np.minimum(cruise, np.sqrt(np.maximum(2.0 * decel * (end - s), 0.0)))
    v[0] = cruise
    return ReferenceProfile("distance", s, v)


def _unplanned_pid(route: Route, ref: ReferenceProfile) -> FreightPid:
    """PID on ``ref`` with the blending's generic air-brake rule only (no planned stop)."""
    params = FreightPidParams(blending=BlendingParams(stop_ed_share=0.0))
    return FreightPid(params, ref, route)


def test_final_stop_never_pulls_against_the_air_brake() -> None:
    """The last 150 m of a 0.2 m/s^2 braking to the stop (the first freight_20km reference):
    even the minimum reduction brakes harder than planned once the electric brake fades, and
    the PID wants traction. While the (modelled) cylinders hold pressure the locomotive may
    only brake, and the plant's achieved force is never traction while its air brake acts
    (after the 0.5 s + 1.5 s traction lag of an earlier demand has decayed: checked from 10 s
    after the first application). Before the fix it demanded 760 kN at 0.55 m/s."""
    route = load_route("freight_20km")
    s0 = 19850.0
    ref = _constant_decel_reference(route)
    pid = _unplanned_pid(route, ref)
    run = closed_loop(pid, route, 60.0, s0=s0, v0=ref.speed(s0))
    air = run["pipe_reduction"] > 0
    assert np.any(air)  # the air brake was needed
    first = np.argmax(air)
    assert np.all(run["force_demand"][first:] <= 0.0)
    late = run["t"] >= run["t"][first] + 10.0
    acting = late & (run["air_brake_force"] > 0)
    assert np.any(acting)
    assert np.all(run["traction_force"][acting] <= 1e3)  # N: lag tail of a braking demand
    assert run["v"][-1] < 0.05  # stopped near the stop (cold start 150 m before it) and held
    assert run["pipe_reduction"][-1] >= BlendingParams().hold_reduction
    assert abs(run["s"][-1] - 20000.0) < 15.0


def test_accel_limits_exclude_traction_while_the_air_brake_acts() -> None:
    ref = ReferenceProfile("distance", np.array([0.0, 500.0]), np.array([15.0, 0.0]))
    blend = FreightBlending(BlendingParams(), ref, Route.flat())
    lo, hi = blend.accel_limits(15.0)
    assert hi > 0 > lo
    # planned braking 0.225 m/s^2 needs the air brake: applied, then only braking is allowed
    force, reduction = blend.blend(0.0, 0.2, 15.0, 0.0, -0.225 * blend.m_eff, 15.0, -0.225,
                                   0.0)
    assert reduction > 0 and force <= 0
    for k in range(1, 50):
        force, _ = blend.blend(0.2 * k, 0.2, 15.0, 0.0, 1e6, 15.0, -0.225, 0.0)
        assert force <= 0.0  # a traction demand is not passed through
    assert blend.accel_limits(15.0)[1] <= 0.0
    assert blend.accel_limits(15.0)[1] == pytest.approx(
        -blend.air_force(blend.pressure_estimate, 15.0) / blend.m_eff)


def test_an_overspeed_does_not_deepen_an_applied_air_brake() -> None:
    """A deeper application cannot be taken back short of a full release: an overspeed while
    the brake is applied is left to the electric brake (the planned braking alone deepens)."""
    ref = ReferenceProfile("distance", np.array([0.0, 500.0]), np.array([15.0, 0.0]))
    blend = FreightBlending(BlendingParams(), ref, Route.flat())
    _, applied = blend.blend(0.0, 0.2, 15.0, 0.0, -0.225 * blend.m_eff, 15.0, -0.225, 0.0)
    assert applied > 0
    for k in range(1, 100):  # 3 km/h too fast, the controller asking for everything
        _, reduction = blend.blend(0.2 * k, 0.2, 15.0, 0.0, -1e8, 15.0 - 3.0 / 3.6, -0.225,
                                   0.0)
        assert reduction == applied
    # not applied yet: an overspeed the electric brake cannot hold applies the minimum
    fresh = FreightBlending(BlendingParams(), ReferenceProfile(
        "distance", np.array([0.0, 1e5]), np.array([15.0, 15.0])), Route.flat())
    _, reduction = fresh.blend(0.0, 0.2, 16.0, 0.0, -1e6, 15.0, 0.0, 0.0)
    assert reduction == BlendingParams().train.min_reduction


def test_tabulated_train_resistance_equals_the_length_share_mean() -> None:
    """The whole-train grade/curve/tunnel resistance table is exact (piecewise linear between
    the tabulated kinks): equal to Route.additional_resistance to rounding everywhere."""
    route = load_route("freight_20km")
    blend = FreightBlending(BlendingParams(), route.reference, route)
    s = np.random.default_rng(7).uniform(-500.0, 21_000.0, 2000)
    length = blend.model.train_length
    exact = route.additional_resistance(s, length) * blend.weight / 1e3 / blend.m_eff
    # cumulative integrals of up to ~4e7 (N/kN m) differenced: ~1e-8 N/kN, ~1e-13 m/s^2
    np.testing.assert_allclose(blend.additional_accel(s), exact, rtol=0, atol=1e-12)
    assert blend.additional_accel(float(s[0])) == pytest.approx(exact[0], abs=1e-12)


def _applied_on_final_braking(s: float, v: float) -> FreightBlending:
    """Blending on freight_20km with the minimum reduction applied long enough to have filled
    every cylinder, the train at ``s`` / ``v`` (m, m/s) on the final braking."""
    route = load_route("freight_20km")
    blend = FreightBlending(BlendingParams(final_approach_distance=0.0), route.reference, route)
    blend.reduction, blend.changed_at = blend.p.train.min_reduction, 0.0
    blend.model.step_brakes(0.0, 40.0, blend.reduction)
    blend.pressure_estimate = float(blend.model.pressure.mean())
    return blend


def test_predicted_stop_is_ordered_by_the_braking_it_assumes() -> None:
    """Held air brake < released with the full electric brake < released, coasting (the
    resistance alone, 0.009 m/s^2, needs longer than the 180 s horizon: inf); a faster train
    stops later."""
    blend = _applied_on_final_braking(19900.0, 5.0)
    held = blend.predicted_stop(5.0, 19900.0, release=False)
    full = blend.predicted_stop(5.0, 19900.0, release=True, share=1.0)
    coast = blend.predicted_stop(5.0, 19900.0, release=True, share=0.0)
    assert 19900.0 < held < full < coast
    assert blend.predicted_stop(6.0, 19900.0, release=False) > held
    # held: ~0.2 m/s^2 of air brake, so about v^2 / (2 * 0.2) = 62 m (the friction coefficient
    # grows as the speed falls: somewhat less)
    assert 40.0 < held - 19900.0 < 65.0


def test_final_approach_releases_only_when_the_air_brake_would_stop_short() -> None:
    """Air-brake alone stopping short and the released train able to stop before the stop
    point: release (the stop point returned); too fast for the electric brake, or too far from
    the stop, or no air brake applied: keep the air brake."""
    blend = _applied_on_final_braking(19900.0, 5.0)
    blend.p = BlendingParams()  # final_approach_distance back to its default (300 m)
    stop = 20000.0
    assert blend.next_stop(19900.0) == stop
    short = blend.predicted_stop(2.5, 19975.0, release=False)
    assert short < stop - blend.p.stop_tolerance
    assert blend._final_approach(2.5, 19975.0) == stop
    assert blend._final_approach(6.0, 19940.0) is None  # released it would overshoot
    assert blend._final_approach(2.5, 19975.0 - 400.0) is None  # beyond the distance
    blend.reduction = 0.0
    assert blend._final_approach(2.5, 19975.0) is None


def test_final_approach_brings_the_train_to_the_stop_point() -> None:
    """The minimum air brake stops the train several metres short once the electric brake
    fades (measured 9.8 m for the PID over the whole route before); the final approach
    releases it and stops the head within 1.5 m of the stop point (the prediction is one
    mass; the head also carries the train's stretch), without power braking, and holds it."""
    route = load_route("freight_20km")
    ref = _constant_decel_reference(route)
    pid = _unplanned_pid(route, ref)
    s0 = 19700.0  # on the reference, 300 m before the stop
    run = closed_loop(pid, route, 100.0, s0=s0, v0=ref.speed(s0))
    assert np.any(run["pipe_reduction"][: len(run["t"]) // 2] > 0)  # air brake was applied
    released = np.flatnonzero(np.diff((run["pipe_reduction"] > 0).astype(int)) == -1)
    assert released.size >= 1  # ... and released for the final approach, before the stop
    assert run["s"][released[0] + 1] < 20000.0 - 5.0
    assert np.all(run["force_demand"][released[0]:] <= 0.0)  # never traction after it
    assert abs(run["s"][-1] - 20000.0) < 1.5
    assert run["v"][-1] < 0.05
    assert run["pipe_reduction"][-1] >= BlendingParams().hold_reduction


def test_approach_force_is_finite_when_coasting_would_not_stop_within_the_horizon() -> None:
    """Released, empty cylinders, 5 m/s 25 m before the stop: the resistance alone would need
    ~9 min (the prediction says inf); the electric brake is then used in full (was nan)."""
    route = load_route("freight_20km")
    blend = FreightBlending(BlendingParams(), route.reference, route)
    blend.final_approach, blend.approach_stop, blend.changed_at = True, 20000.0, 0.0
    assert blend.predicted_stop(5.0, 19975.0, True, 0.0, 100.0) == np.inf
    force = blend._approach_force(100.0, 5.0, 19975.0)
    assert force == -blend.model.traction_limits(5.0)[1]


def _reference_predicted_stop(blend: FreightBlending, v: float, s: float, release: bool,
                              share: float, released_for: float, h: float = 0.25,
                              horizon: float = 180.0) -> float:
    """The stop prediction's loop as first written (numpy interpolation, the model's methods):
    the reference for the inlined plain-float loop that runs in the controllers."""
    from plants.freight import friction_coefficient_at

    model, tp = blend.model, blend.p.train
    n = int(horizon / h) + 1
    air_scale = blend.air_scale_schedule(release, released_for, h, n)
    decay = np.exp(-h / tp.traction_time_constant)
    force = min(blend.force, 0.0)
    lag_steps = int(round(tp.traction_delay / h))

    def decel(k: int, vk: float, sk: float, f_loco: float) -> float:
        mu = friction_coefficient_at(vk)
        return (air_scale[k] * mu - f_loco) / blend.m_eff + blend.resistance_accel(vk, sk)

    vk, sk = max(v, 0.0), s
    for k in range(n - 1):
        if release and k >= lag_steps:
            target = -share * model.traction_limits(vk)[1]
            force = target + (force - target) * decay
        a0 = decel(k, vk, sk, force)
        if a0 <= 0.0 and vk <= 0.0:
            return sk
        vm = vk - 0.5 * h * a0
        if vm <= 0.0:
            return sk + vk * vk / (2.0 * a0)
        am = decel(k, vm, sk + 0.5 * h * vk, force)
        v1 = vk - h * am
        if v1 <= 0.0:
            return sk + vk * vk / (2.0 * am)
        sk += 0.5 * h * (vk + v1)
        vk = v1
    return np.inf


def test_fast_stop_prediction_equals_the_numpy_reference() -> None:
    """The inlined plain-float loop of ``predicted_stop`` against the numpy reference on random
    states on the final braking and on grades (applied / releasing cylinders, electric brake
    shares, speeds). The same IEEE operations in the same order: equal to the bit on this
    CPU; allowed 1e-9 m anywhere (np.interp compiled with fused multiply-adds changes the
    resistance by <= 1 ulp (~2e-18 m/s^2) per evaluation; over <= 720 midpoint steps of
    0.25 s that moves the stop by <= 0.5 * 180^2 * 2e-18 ~ 3e-14 m, far below 1e-9 m)."""
    rng = np.random.default_rng(7)
    worst, finite = 0.0, 0
    for _ in range(40):
        s = float(rng.uniform(1000.0, 19990.0))
        v = float(rng.uniform(0.0, 15.0))
        blend = _applied_on_final_braking(s, v)
        blend.model.step_brakes(40.0, 40.0 + float(rng.uniform(0.0, 30.0)),
                                float(rng.choice([0.0, blend.reduction])))
        blend.force = float(rng.uniform(-4e5, 1e5))
        for release, share, released_for in ((False, 1.0, 0.0), (True, 0.0, 0.0),
                                             (True, 1.0, float(rng.uniform(0.0, 20.0))),
                                             (True, float(rng.uniform()), 5.0)):
            fast = blend.predicted_stop(v, s, release, share, released_for)
            ref = _reference_predicted_stop(blend, v, s, release, share, released_for)
            if np.isinf(ref):
                assert fast == ref
            else:
                worst, finite = max(worst, abs(fast - ref)), finite + 1
    assert finite >= 60  # most cases stop within the horizon
    assert worst <= 1e-9


def test_interp_at_equals_np_interp() -> None:
    """The plain-float interpolation against np.interp: at the knots, between them, beyond
    both ends (held end values), on the blending's resistance table. Same operations: allowed
    1 ulp of the table's largest value (a compiled np.interp may fuse the multiply-add)."""
    from controllers.common.freight_blending import interp_at

    route = load_route("freight_20km")
    blend = FreightBlending(BlendingParams(), route.reference, route)
    xp, fp = blend._add_knots, blend._add_values
    rng = np.random.default_rng(3)
    x = np.concatenate((xp, rng.uniform(xp[0] - 100.0, xp[-1] + 100.0, 2000),
                        [xp[0] - 1.0, xp[-1] + 1.0]))
    fast = np.array([interp_at(float(q), xp.tolist(), fp.tolist()) for q in x])
    np.testing.assert_allclose(fast, np.interp(x, xp, fp), rtol=0,
                               atol=np.spacing(np.abs(fp).max()))
    assert interp_at(float(xp[3]), xp.tolist(), fp.tolist()) == fp[3]


@pytest.mark.parametrize("case", ["planned application", "release overtaken by a re-application"])
def test_air_force_ahead_equals_the_plant_brake_model_stepped_forward(case: str) -> None:
    """The blending's prediction of the air-brake force ahead (the optimal preview's air-brake
    disturbance) equals the plant's brake-pipe model stepped to each time at the plant's
    0.01 s step with the same commands: from rest with a planned application 2 s ahead, and
    a release whose slower wave a re-application 1 s later overtakes at the rear vehicles
    (the plant's latest-arrived rule). eq. (9) composes exactly over sub-steps, so the
    tolerance is rounding of the powers (1e-9 relative)."""
    route = load_route("freight_20km")
    blend = FreightBlending(BlendingParams(), route.reference, route)
    plant = FreightTrain(BlendingParams().train, route)
    if case == "planned application":
        commands, now, planned = [], 0.0, (2.0, 50e3)
    else:
        commands, now, planned = [(0.0, 60e3), (8.0, 0.0)], 8.4, (9.0, 50e3)
    for t0, r in commands:  # the blending's model has seen the commands up to now
        blend.model.brake_history.append([t0, r])
    k_now = round(now / 0.2)
    for k in range(k_now):
        blend.model.step_brakes(0.2 * k, 0.2 * (k + 1), blend.model.brake_history[-1][1])
    times = now + np.arange(0.0, 40.0, 0.5)
    speeds = np.linspace(20.0, 8.0, times.size)
    predicted = blend.air_force_ahead(now, times, speeds, planned)
    schedule = [*commands, planned]
    expected, t, h = [], 0.0, 0.01
    for t_j, v_j in zip(times, speeds):
        while t < t_j - 1e-9:
            r = [c for c in schedule if c[0] <= t + 1e-9]
            plant.step_brakes(t, t + h, r[-1][1] if r else 0.0)
            t += h
        expected.append(float(plant.brake_scale @ plant.pressure) * friction_coefficient_at(v_j))
    expected = np.array(expected)
    assert expected.max() > 1e6  # N: the brakes act within the horizon
    np.testing.assert_allclose(predicted, expected, rtol=1e-9, atol=1e-3)
    if case != "planned application":  # the re-application reached every vehicle
        assert np.all(plant.pressure > 0.0)


def test_a_start_creep_under_stop_speed_is_not_held() -> None:
    """A reference that starts with a creep under ``stop_speed`` at zero acceleration (the
    planned start of freight_20km: the head takes up the stretch at 0.1 km/h) is not the end of
    the profile: no holding brake there, the locomotive pulls; at the profile's end, below
    ``stop_speed`` and nothing faster ahead, the train is held."""
    creep = 0.03  # m/s
    ref = ReferenceProfile("distance", np.array([0.0, 0.01, 0.3, 10.0, 400.0, 500.0]),
                           np.array([0.0, creep, creep, 2.0, 2.0, 0.0]))
    blend = FreightBlending(BlendingParams(), ref, Route.flat())
    assert ref.accel(0.1) == 0.0 and creep < blend.p.stop_speed
    assert blend.peak_ahead(0.1) == 2.0 and blend.peak_ahead(499.9) == 0.0
    force, reduction = blend.blend(0.0, 0.2, creep, 0.1, 1e5, creep, 0.0, 0.0)
    assert not blend.holding and reduction == 0.0 and force == 1e5
    end = FreightBlending(BlendingParams(), ref, Route.flat())
    _, reduction = end.blend(0.0, 0.2, 0.1, 499.9, 0.0, ref.speed(499.9), 0.0, 0.0)
    assert end.holding and reduction == BlendingParams().hold_reduction
