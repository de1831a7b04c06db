"""Tube sets of RMPC/RSMPC: W bound, stabilising K, terminal weight (eq. 19), nested and
robustly invariant reachable sets (sampled disturbances), and tightened constraints."""

from __future__ import annotations

import numpy as np
import pytest

from controllers.mpc.stop_mpc import StopMpcParams, TubeStopMpc, disturbance_bounds
from plants.route import GRAVITY, load_route

EPS = np.finfo(float).eps


@pytest.fixture(scope="module")
def rmpc() -> TubeStopMpc:
    return TubeStopMpc(StopMpcParams(horizon=10))


def test_disturbance_bound_from_grades_and_davis(rmpc):
    p = rmpc.p
    lo, hi = disturbance_bounds(p, load_route("seed000_stop"))
    assert lo == pytest.approx(GRAVITY * -6 / 1000 + p.davis.force(0.0) / p.mass * 0.8)
    assert hi == pytest.approx(GRAVITY * 28 / 1000 + p.davis.force(20.0) / p.mass * 1.2)
    assert lo < 0.0 < hi


def test_feedback_stabilises_and_terminal_weight_satisfies_eq19(rmpc):
    assert np.max(np.abs(np.linalg.eigvals(rmpc.A_cl))) < 1.0
    lhs = rmpc.Q + rmpc.p.r_du * np.outer(rmpc.K, rmpc.K) + rmpc.A_cl.T @ rmpc.P @ rmpc.A_cl \
        - rmpc.P
    assert np.max(np.linalg.eigvalsh(0.5 * (lhs + lhs.T))) <= 1e-6 * np.max(np.abs(rmpc.P))


DIRS = np.vstack([np.eye(4), -np.eye(4)])


@pytest.mark.parametrize("hold,last", [(1, 25), (3, 3), (6, 6)])
def test_reachable_sets_are_nested(rmpc, hold, last):
    """R_i (M = 1) grow with i (0 in W); R_i^M too while the input is held (i <= M): after
    that A_cl contracts the held-input part, so R_i^M need not be nested."""
    prev = np.zeros(len(DIRS))
    for i in range(1, last + 1):
        lo, hi = rmpc.tightening(i, np.eye(4), hold)
        h = np.concatenate([hi, lo])
        # R_i is a sum of i supports, each rounded a few times: 4 i ulps of the largest
        assert np.all(h >= prev - 4 * i * EPS * np.abs(h).max())
        prev = h


@pytest.mark.parametrize("hold", [1, 4])
def test_sampled_disturbances_stay_in_reachable_sets(rmpc, hold):
    """e_{i+1} = A e_i + w (i < M, input held), then A_cl e + w: e_i in R_i^M (box support)."""
    rng = np.random.default_rng(7)
    lo_w, hi_w = rmpc.w_bounds
    g = rmpc.model.g
    for _ in range(200):
        e = np.zeros(4)
        for i in range(1, 30):
            w = g * rng.choice([lo_w, hi_w, rng.uniform(lo_w, hi_w)])
            e = (rmpc.model.A if i <= hold else rmpc.A_cl) @ e + w
            lo, hi = rmpc.tightening(i, np.eye(4), hold)
            assert np.all(e <= hi + 1e-9) and np.all(-e <= lo + 1e-9)


def test_mrpi_bound_is_robustly_invariant_under_sampling(rmpc):
    rng = np.random.default_rng(11)
    z = rmpc.mrpi_box(np.eye(4))
    lo_w, hi_w = rmpc.w_bounds
    e = np.zeros(4)
    for _ in range(5000):
        e = rmpc.A_cl @ e + rmpc.model.g * rng.uniform(lo_w, hi_w)
        assert np.all(e <= z[4:] + 1e-9) and np.all(-e <= z[:4] + 1e-9)


def test_tightened_constraints_shrink_along_the_horizon(rmpc):
    qp = rmpc.qp(1)
    his = np.array(qp._hi[:-1])  # stage constraints 1..H (terminal box excluded)
    los = np.array(qp._lo[:-1])
    # bound minus a sum of up to H supports: 4 H ulps of the bounds
    tol = 4 * len(his) * EPS * max(np.abs(his).max(), np.abs(los).max())
    assert np.all(np.diff(his[:, 0]) <= tol)  # u_max tightened more and more
    assert np.all(np.diff(los[:, 3]) >= -tol)  # position error lower bound rises
    assert his[-1, 0] < rmpc.p.u_max and los[-1, 3] > -rmpc.p.position_error_max


def test_ideal_mpc_has_no_tightening():
    from controllers.mpc.stop_mpc import IdealStopMpc

    ideal = IdealStopMpc(StopMpcParams(horizon=5))
    assert ideal.w_bounds == (0.0, 0.0)
    lo, hi = ideal.tightening(5, np.eye(4))
    assert np.all(lo == 0) and np.all(hi == 0)


def test_spread_bound_from_mass_davis_and_grade_spread(rmpc):
    from controllers.mpc.stop_mpc import spread_bounds

    p = rmpc.p
    lo, hi = spread_bounds(p, load_route("seed000_stop"))
    a_w = p.davis.force(p.v_max) / p.mass
    a_g = p.grade_uncertainty * GRAVITY * 28 / 1000  # largest |grade| of the route
    assert lo == pytest.approx(a_w * ((1 - p.davis_uncertainty) / (1 + p.mass_uncertainty) - 1)
                               - a_g)
    assert hi == pytest.approx(a_w * ((1 + p.davis_uncertainty) / (1 - p.mass_uncertainty) - 1)
                               + a_g)
    assert rmpc.w_bounds == (lo, hi)


def test_nominal_resistance_shrinks_the_tube(rmpc):
    """W of the spread only, against W of the whole resistance: a narrower mRPI set along
    every coordinate (the whole-resistance W is lopsided, so not in every single direction)
    and less tightening (lower plus upper) of every stage constraint."""
    whole = TubeStopMpc(StopMpcParams(horizon=10, nominal_resistance=False))
    lo_s, hi_s = rmpc.w_bounds
    lo_w, hi_w = whole.w_bounds
    assert hi_s - lo_s < 0.5 * (hi_w - lo_w)
    z_s, z_w = rmpc.mrpi_box(np.eye(4)), whole.mrpi_box(np.eye(4))
    assert np.all(z_s[:4] + z_s[4:] < z_w[:4] + z_w[4:])
    for i in (1, 5, 10):
        t_s = np.sum(rmpc.tightening(i, rmpc.F), axis=0)  # lower rise + upper fall per row
        t_w = np.sum(whole.tightening(i, whole.F), axis=0)
        assert np.all(t_s <= t_w) and np.sum(t_s) < np.sum(t_w)


def test_w_a_point_gives_no_tightening():
    core = TubeStopMpc(StopMpcParams(horizon=6, mass_uncertainty=0.0, davis_uncertainty=0.0,
                                     grade_uncertainty=0.0))
    for i in (1, 3, 6):
        lo, hi = core.tightening(i, np.eye(4))
        assert np.all(lo == 0) and np.all(hi == 0)


def _lp_max(f, rows, rhs):
    from scipy.optimize import linprog

    res = linprog(-f, A_ub=rows, b_ub=rhs, bounds=[(None, None)] * len(f), method="highs")
    assert res.status == 0
    return -res.fun


@pytest.mark.parametrize("kw", [{}, {"nominal_resistance": False},
                                {"disturbance_observer": True, "grade_uncertainty": 0.1}])
def test_terminal_set_is_robustly_invariant_inside_x(kw):
    """For each row f of Sigma: max over e in Sigma of f A_cl e, plus the support of W in f,
    is within the row's bound (LP: A_cl Sigma (+) W subset Sigma), and every constraint of X
    holds on Sigma. LP (HiGHS) feasibility tolerance 1e-7 on rows of norm up to ~1e2."""
    core = TubeStopMpc(StopMpcParams(horizon=10, **kw))
    rows, rhs = core.F_term, core.h_term
    C, h = core.terminal_constraints()
    W = core.w_vertices
    tol = 1e-6 * max(1.0, np.abs(rhs).max())
    for f, b in zip(rows, rhs, strict=True):
        assert _lp_max(f @ core.A_cl, rows, rhs) + np.max(W @ f) <= b + tol
    for f, b in zip(C, h, strict=True):
        assert _lp_max(f, rows, rhs) <= b + tol
    # and it is not trivially small: it holds the mRPI outer bound's vertices in (v, s)
    z = core.mrpi_box(np.eye(4))
    assert np.all(rows @ np.zeros(4) <= rhs)
    assert z[6] < _lp_max(np.eye(4)[3], rows, rhs)


def test_terminal_set_invariance_under_sampled_disturbances(rmpc):
    rng = np.random.default_rng(3)
    rows, rhs = rmpc.F_term, rmpc.h_term
    lo_w, hi_w = rmpc.w_bounds
    e = np.zeros(4)
    for _ in range(3000):
        e = rmpc.A_cl @ e + rmpc.model.g * rng.choice([lo_w, hi_w, rng.uniform(lo_w, hi_w)])
        assert np.all(rows @ e <= rhs + 1e-9 * np.abs(rhs).max())
