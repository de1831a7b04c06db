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
