"""Seed 002 baselines: sliding mode (reaching law) and fuzzy PID (rule surface table)."""

from __future__ import annotations

import numpy as np
import pytest
import skfuzzy as fuzz

from controllers.fuzzy.fuzzy_pid import (
    KI_RULES,
    KP_RULES,
    TERMS,
    FreightFuzzyPid,
    FuzzyPidParams,
    RuleSurface,
    infer,
)
from controllers.smc.sliding_mode import FreightSlidingMode, SlidingModeParams
from plants.route import ReferenceProfile, Route


def _profile() -> ReferenceProfile:
    return ReferenceProfile("distance", np.array([0.0, 1e6]), np.array([10.0, 10.0]))


@pytest.mark.parametrize("sigma0", [2.0, -1.5])
def test_smc_reaches_its_surface_in_finite_steps_on_the_nominal_plant(sigma0: float) -> None:
    """Nominal plant v(k+1) = v(k) + T (u - a_res): the reaching law gives
    sigma(k+1) = (1 - qT) sigma - eps T sgn(sigma), so |sigma| <= eps T after at most
    |sigma0| / (eps T) steps, and it stays in that band (chattering)."""
    p = SlidingModeParams()
    smc = FreightSlidingMode(p, _profile(), Route.flat())
    T, a_res, a_ref = p.sample_time, 0.01, 0.0
    v, R = 10.0 - sigma0, 10.0
    sigmas = []
    for _ in range(400):
        e = R - v
        u = smc.law(e, a_ref, a_res)
        smc.integral += T * e
        sigmas.append(smc.sigma)
        v += T * (u - a_res)
    band = p.eps * T
    # |sigma| ~ 0.1: each step adds a few roundings (~1e-17); 1e-12 only absorbs those
    reached = int(np.argmax(np.abs(sigmas) <= band + 1e-12))
    assert abs(sigmas[0]) > band
    assert reached <= int(np.ceil(abs(sigma0) / band))
    assert np.all(np.abs(sigmas[reached:]) <= band + 1e-12)
    signs = np.sign(sigmas[reached:])
    assert np.count_nonzero(np.diff(signs)) > 100  # sgn keeps switching: chattering


def test_fuzzy_table_equals_the_inference_at_its_nodes_and_interpolates_between() -> None:
    for rules in (KP_RULES, KI_RULES):
        surface = RuleSurface(rules, 7)
        # at a node the table holds the inference's own value (bilinear weights 1 and 0):
        # equal up to a few roundings of O(1) numbers
        for E in surface.axis:
            for EC in surface.axis:
                assert surface(E, EC) == pytest.approx(infer(E, EC, rules), abs=1e-12)
        # between nodes: bilinear, within the range of the four corners
        val = surface(0.5, -0.5)
        corners = [surface(a, b) for a in (0.0, 1.0) for b in (-1.0, 0.0)]
        assert min(corners) - 1e-12 <= val <= max(corners) + 1e-12


def test_fuzzy_inference_applies_the_rule_table_at_the_term_centres() -> None:
    """At term centres exactly one rule fires with strength 1: the output is the centroid of
    the consequent term (the centre, the edge terms' half triangles shifted inwards)."""
    universe = np.linspace(-3.0, 3.0, 601)
    for rules in (KP_RULES, KI_RULES):
        for i, E in enumerate(range(-3, 4)):
            for j, EC in enumerate(range(-3, 4)):
                k = TERMS.index(rules[i][j])
                c = k - 3.0
                mf = fuzz.trimf(universe, [c - 1, c, c + 1])
                assert infer(E, EC, rules) == pytest.approx(
                    fuzz.defuzz(universe, mf, "centroid"), abs=1e-9)
    assert infer(3, 3, KP_RULES) == pytest.approx(-3.0 + 1.0 / 3.0, abs=1e-9)  # NB


def test_fuzzy_pid_gains_follow_the_rule_table() -> None:
    """Large error, not changing (E = PB, EC = ZO): Kp rule NM (-2), Ki rule PM (+2)."""
    p = FuzzyPidParams()
    fpid = FreightFuzzyPid(p, _profile(), Route.flat())
    v = 10.0 - 3 * p.e_scale
    fpid.compute(0.0, {"v": v, "s": 0.0})
    fpid.compute(0.2, {"v": v, "s": 2.0})
    assert fpid.kp_now == pytest.approx(p.kp - 2 * p.kp_scale, abs=1e-9)
    assert fpid.ki_now == pytest.approx(p.ki + 2 * p.ki_scale, abs=1e-9)


@pytest.mark.parametrize("name", ["preview", "smc", "fpid", "pid"])
def test_controller_state_restore_reproduces_the_rest(name: str) -> None:
    """get_state mid-run, continue, set_state, rerun: identical outputs (complete state,
    blending and its brake model included, the preview's train-mean observer), on the final
    braking with the air brake."""
    from controllers.pid.freight_pid import FreightPid, FreightPidParams
    from controllers.preview.preview import FreightPreview, PreviewParams
    from plants.route import load_route

    core_class, params = {"preview": (FreightPreview, PreviewParams()),
                          "smc": (FreightSlidingMode, SlidingModeParams()),
                          "fpid": (FreightFuzzyPid, FuzzyPidParams()),
                          "pid": (FreightPid, FreightPidParams())}[name]
    route = load_route("freight_20km")
    core = core_class(params, route.reference, route)
    rng = np.random.default_rng(5)
    s = np.linspace(19000.0, 19400.0, 80)
    v = np.array([route.reference.speed(x) for x in s]) + 0.3 * rng.normal(size=s.size)

    def step(k: int) -> tuple:
        out, _ = core.compute(0.2 * k, {"v": float(v[k]), "s": float(s[k])})
        return tuple(sorted(out.items()))

    for k in range(30):
        step(k)
    state = core.get_state()
    first = [step(k) for k in range(30, 80)]
    core.set_state(state)
    second = [step(k) for k in range(30, 80)]
    assert first == second
    assert any(dict(o)["pipe_reduction"] > 0 for o in first)  # the air brake took part


def test_smc_boundary_layer_stops_the_chattering_inside_the_layer() -> None:
    """With sat(sigma / phi) the law on the nominal plant is, inside the layer,
    sigma(k+1) = (1 - q T - eps T / phi) sigma(k): a geometric decay with that exact ratio,
    no sign switch (until it reaches rounding level), |sigma| <= phi from the entry on;
    with sgn (phi = 0) sigma keeps switching sign in the band eps T."""
    from dataclasses import replace

    base = SlidingModeParams()
    phi = base.eps / base.q  # the entry's layer width: in the layer eps/phi = q
    T, a_res = base.sample_time, 0.01
    ratio = 1.0 - base.q * T - base.eps * T / phi
    assert 0.0 < ratio < 1.0
    runs = {}
    for width in (0.0, phi):
        smc = FreightSlidingMode(replace(base, boundary_layer=width), _profile(), Route.flat())
        v, sigmas = 10.0 - 2.0, []
        for _ in range(400):
            e = 10.0 - v
            u = smc.law(e, 0.0, a_res)
            smc.integral += T * e
            sigmas.append(smc.sigma)
            v += T * (u - a_res)
        runs[width] = np.array(sigmas)
    inside = runs[phi]
    entry = int(np.argmax(np.abs(inside) <= phi))
    assert entry > 0 and np.all(np.abs(inside[entry:]) <= phi)
    tail = inside[entry:entry + 50]
    # each step is a few roundings of numbers of order phi: relative 1e-12 absorbs them
    np.testing.assert_allclose(tail[1:], ratio * tail[:-1], rtol=0, atol=1e-12 * phi)
    assert np.all(np.sign(tail) == np.sign(tail[0]))  # (later it decays to rounding level)
    assert np.count_nonzero(np.diff(np.sign(runs[0.0][100:]))) > 100


def test_fuzzy_pid_feedforward_is_the_pids_term() -> None:
    """reference_feedforward adds exactly the freight PID's a_ref(s + v t_p) to the fuzzy
    PID's demand: same state, same sample, the demands differ by the PID's a_ref output."""
    from dataclasses import replace

    from controllers.pid.freight_pid import FreightPid, FreightPidParams
    from plants.route import load_route

    route = load_route("freight_20km")
    # the PID's look-ahead set to the fuzzy PID's: the same a_ref(s + v t_p)
    pid = FreightPid(FreightPidParams(preview_time=FuzzyPidParams().preview_time),
                     route.reference, route)
    plain = FreightFuzzyPid(FuzzyPidParams(), route.reference, route)
    fed = FreightFuzzyPid(replace(FuzzyPidParams(), reference_feedforward=True),
                          route.reference, route)
    s = 1000.0  # on the traction ramp: a_ref > 0, the demand inside its bounds
    v = route.reference.speed(s) + 0.1
    a_pid = pid.compute(0.0, {"v": v, "s": s})[0]["a_ref"]
    out_plain = plain.compute(0.0, {"v": v, "s": s})[0]
    out_fed = fed.compute(0.0, {"v": v, "s": s})[0]
    assert a_pid != 0.0 and out_fed["a_ref"] == a_pid
    lo, hi = fed.blending.accel_limits(v)
    assert lo < out_fed["accel_demand"] < hi
    assert out_fed["accel_demand"] - out_plain["accel_demand"] == pytest.approx(a_pid,
                                                                                rel=1e-12)


@pytest.mark.parametrize("name", ["preview", "smc", "fpid", "pid"])
def test_every_law_feeds_back_the_observed_blend(name: str) -> None:
    """Every freight law carries the train-mean observer and feeds back
    (1 - w) v_head + w v_mean (the same IEEE operations: exact); its demand then differs
    from the same law's with w = 0, which feeds back the head speed exactly."""
    from dataclasses import replace

    from controllers.pid.freight_pid import FreightPid, FreightPidParams
    from controllers.preview.preview import FreightPreview, PreviewParams
    from plants.route import load_route

    core_class, params = {"preview": (FreightPreview, PreviewParams()),
                          "smc": (FreightSlidingMode, SlidingModeParams()),
                          "fpid": (FreightFuzzyPid, FuzzyPidParams()),
                          "pid": (FreightPid, FreightPidParams())}[name]
    route = load_route("freight_20km")
    w = 0.5
    blended = core_class(replace(params, mean_weight=w), route.reference, route)
    head = core_class(replace(params, mean_weight=0.0), route.reference, route)
    s0, v0 = 5000.0, route.reference.speed(5000.0)
    diff = 0.0
    for k in range(20):
        v, s = v0 + 0.02 * np.sin(k), s0 + v0 * 0.2 * k
        out = blended.compute(0.2 * k, {"v": v, "s": s})[0]
        assert blended.v_feedback == (1.0 - w) * v + w * blended.observer.speed
        ref = head.compute(0.2 * k, {"v": v, "s": s})[0]
        diff = max(diff, abs(out["accel_demand"] - ref["accel_demand"]))
    assert diff > 0.0  # the observer changes the demand of every law
    assert head.v_feedback == v  # w = 0: the head speed, exactly
