"""Control model of seed 004's hybrid MPC: PWA resistance fit, PWA system, its MLD form."""

from __future__ import annotations

import numpy as np
import pytest

from controllers.hybrid.model import KN, ChainModel, Limits, PwlResistance
from plants.emu import emu_config

V_FIT = 350.0 / 3.6


def _train():
    return emu_config("crh3_3car")


def _resistance() -> PwlResistance:
    p = _train()
    return PwlResistance.fit(sum(p.davis_a), sum(p.davis_b), sum(p.davis_c), sum(p.masses),
                             V_FIT)


def _model() -> ChainModel:
    p = _train()
    return ChainModel(p.masses, p.coupler_stiffness, p.coupler_damping, _resistance(), 1.0,
                      motored=[f > 0 for f in p.max_traction_force])


def _random_state(rng: np.random.Generator, md: ChainModel) -> np.ndarray:
    v = rng.uniform(0.0, 90.0) + rng.normal(0.0, 0.01, md.n)
    x = np.concatenate([[0.0], -np.cumsum(rng.normal(0.0, 1e-3, md.n - 1))])
    return np.concatenate([v, x])


def _limits(md: ChainModel) -> Limits:
    trac = np.where(md.motored, 70.75, 0.0)
    return Limits(trac, np.array([49.5, 50.4, 54.0]))


def test_pwa_fit_is_continuous_and_close_to_the_davis_curve() -> None:
    p, res = _train(), _resistance()
    mass = sum(p.masses)
    assert len(res.alpha) == 3 and np.all(np.diff(res.beta) > 0)  # convex, like v^2
    for k, vk in enumerate(res.breakpoints):
        assert res.alpha[k] + res.beta[k] * vk == pytest.approx(
            res.alpha[k + 1] + res.beta[k + 1] * vk, abs=1e-12)
    v = np.linspace(0.0, V_FIT, 1001)
    davis = (sum(p.davis_a) + sum(p.davis_b) * v + sum(p.davis_c) * v * v) / mass
    fit = np.array([res(x) for x in v])
    # the chord of c v^2 over a segment of width h is off by c h^2 / 8 at most; a least-squares
    # continuous fit spreads that error, staying within twice the chord's
    h = V_FIT / 3
    assert np.max(np.abs(fit - davis)) <= 2 * (sum(p.davis_c) / mass) * h * h / 8


def test_mld_reproduces_the_pwa_model_on_random_states_and_inputs() -> None:
    md, rng = _model(), np.random.default_rng(4)
    lim = _limits(md)
    for _ in range(300):
        x = _random_state(rng, md)
        delta = int(rng.integers(0, 2))
        u = (rng.uniform(0.0, 1.0, md.n) * lim.traction if delta
             else -rng.uniform(0.0, 1.0, md.n) * lim.brake)
        w = md.aux(x, u, delta)
        assert md.mld_feasible(x, w, lim)
        # same arithmetic in another order: rounding of |x| ~ 1e2
        np.testing.assert_allclose(md.mld_step(x, w), md.pwa_step(x, u), rtol=0, atol=1e-10)
        # any other segment choice violates the big-M rows (unless on a breakpoint)
        v = float(md.c @ x)
        if min(abs(v - vk) for vk in md.res.breakpoints) > 1e-6:
            for k in range(md.K):
                bad = w.copy()
                bad[md.i_b(k)] = 1.0 - bad[md.i_b(k)]
                assert not md.mld_feasible(x, bad, lim)


def test_mean_speed_obeys_the_momentum_balance() -> None:
    """c'x+ = c'x + Ts (sum u / M - w(c'x)): couplers are internal forces."""
    md, rng = _model(), np.random.default_rng(7)
    for _ in range(50):
        x = _random_state(rng, md)
        u = rng.uniform(-50.0, 50.0, md.n)
        v = float(md.c @ x)
        expected = v + md.Ts * (KN * u.sum() / md.m.sum() - md.res(v))
        assert float(md.c @ md.pwa_step(x, u)) == pytest.approx(expected, abs=1e-10)


def test_traction_mode_never_lets_a_trailer_brake() -> None:
    """Property: with delta = 1 every force the MLD admits is >= 0 and the trailer's is 0."""
    md, rng = _model(), np.random.default_rng(11)
    lim = _limits(md)
    trailer = np.nonzero(~md.motored)[0]
    assert trailer.size == 1
    for _ in range(500):
        x = _random_state(rng, md)
        u = rng.uniform(-60.0, 80.0, md.n)
        if rng.random() < 0.3:
            u[trailer] = 0.0
        w = md.aux(x, u, 1)
        admissible = bool(np.all(u >= 0) and np.all(u <= lim.traction))
        assert md.mld_feasible(x, w, lim) == admissible
        if md.mld_feasible(x, w, lim):
            assert u[trailer[0]] == 0.0


def test_coupler_rows_match_the_plant_definition() -> None:
    md, p = _model(), _train()
    x = np.array([30.0, 29.9, 29.95, 0.0, -0.002, -0.003])
    f = md.coupler_forces(x) * KN
    k, d = p.coupler_stiffness, p.coupler_damping
    assert f[0] == pytest.approx(k * 0.002 + d * 0.1)
    assert f[1] == pytest.approx(k * 0.001 - d * 0.05)


def test_bad_model_data_is_rejected() -> None:
    with pytest.raises(ValueError, match="masses"):
        ChainModel([1.0, -1.0], 1.0, 1.0, _resistance())
    with pytest.raises(ValueError, match="speed_range"):
        ChainModel([1.0, 1.0], 1.0, 1.0, _resistance(), speed_range=(0.0, 10.0))
