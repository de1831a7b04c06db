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
