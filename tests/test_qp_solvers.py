"""DAQP (default) and OSQP on QPs recorded from the seed 000 closed loops (issue 10).

Reference for each recorded QP: the KKT system on DAQP's active set, solved directly
(``numpy.linalg.solve``) and certified optimal by the KKT conditions (primal feasibility of
that point and the sign of every active multiplier: sufficient for a convex QP). Tolerances:

* DAQP is exact up to rounding: ``|U - U*|_inf <= m eps cond(K) max(1, |U*|_inf)``, ``m`` the
  size of the KKT matrix ``K`` (the forward-error bound of a backward-stable solve, which
  bounds DAQP's LDL' path as well; measured up to 0.2 of it).
* OSQP stops once its primal and dual residuals are below ``eps_abs + eps_rel * norm``
  (recomputed here at its answer). A dual residual ``r`` makes OSQP's point the exact optimum
  of the QP with linear term ``q - r``; the optimum is ``1/mu``-Lipschitz in ``q`` (``mu``
  the smallest eigenvalue of the Hessian), so ``|U - U*|_2 <= sqrt(n) eps_dual / mu``.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from mpc_loop import run_loop

from controllers.common.qp import HorizonQP
from controllers.mpc.stop_mpc import IdealStopMpc, SelfTriggeredStopMpc, StopMpcParams, TubeStopMpc

EPS = np.finfo(float).eps
CASES = [(TubeStopMpc, 10), (IdealStopMpc, 5), (SelfTriggeredStopMpc, 6)]


def record(cls, N: int, every: int = 5):
    """Every ``every``-th feasible QP solved (DAQP) in the closed loop of ``cls`` at horizon N
    (the tightened problems: not the fallback's, not the infeasible ones at standstill)."""
    calls = []
    original = HorizonQP.solve

    def spy(self, x0, ref, d=None, warm_x=None, warm_y=None):
        res = original(self, x0, ref, d, warm_x, warm_y)
        if res.feasible and self is not core.fallback_qp():
                calls.append((self, x0.copy(), ref.copy(), None if d is None else d.copy(),
                          None if warm_y is None else np.array(warm_y), res))
        return res

    p = replace(StopMpcParams(), horizon=N)
    core = cls(p)
    HorizonQP.solve = spy
    try:
        run_loop(core, p)
    finally:
        HorizonQP.solve = original
    return p, calls[::every]


def vectors(qp: HorizonQP, x0, ref, d):
    """(q, low, high) of ``min U'Hh U + q'U  s.t.  low <= Acon U <= high`` (as solve builds)."""
    z = qp._W @ np.concatenate((x0, ref.ravel(), np.zeros(qp.H) if d is None else d))
    a, b = qp._split
    low = qp._lo_all - z[b:]
    return z[a:b], low, np.maximum(qp._hi_all - z[b:], low)


def kkt_reference(qp: HorizonQP, q, low, high, dual):
    """Optimum on the active set of ``dual`` by a direct KKT solve: (U, y, tolerance)."""
    P, A = 2.0 * qp.Hhalf, qp.Acon
    act = np.flatnonzero(dual)
    bound = np.where(dual[act] > 0, high[act], low[act])
    n, k = P.shape[0], len(act)
    K = np.block([[P, A[act].T], [A[act], np.zeros((k, k))]])
    sol = np.linalg.solve(K, np.concatenate([-q, bound]))
    U, y = sol[:n], np.zeros(A.shape[0])
    y[act] = sol[n:]
    tol = (n + k) * EPS * np.linalg.cond(K) * max(1.0, np.max(np.abs(U)))
    # certificate: feasible, and every multiplier pushes the way its bound does
    AU = A @ U
    scale = tol * max(1.0, np.max(np.abs(A)))
    assert np.all(AU >= low - scale) and np.all(AU <= high + scale)
    free = low[act] < high[act]  # equality rows (low == high) may take either sign
    assert np.all(np.sign(y[act][free]) == np.sign(dual[act][free]))
    return U, y, tol


@pytest.mark.parametrize("cls,N", CASES)
def test_daqp_is_exact_on_recorded_qps(cls, N):
    _, calls = record(cls, N)
    assert len(calls) > 20
    n_active = 0
    for qp, x0, ref, d, _, res in calls:
        assert res.feasible and res.status == "solved"
        q, low, high = vectors(qp, x0, ref, d)
        U, y, tol = kkt_reference(qp, q, low, high, res.dual)
        np.testing.assert_allclose(res.U, U, rtol=0, atol=tol)
        n_active += np.count_nonzero(res.dual)
    if cls is not IdealStopMpc:  # the tube cases do run into their constraints
        assert n_active > 0


@pytest.mark.parametrize("cls,N", CASES)
def test_osqp_within_its_tolerance_of_the_exact_optimum(cls, N):
    p, calls = record(cls, N)
    osqp_core = cls(replace(p, qp_solver="osqp"))
    for qp, x0, ref, d, _, res in calls:
        oq = osqp_core.qp(qp.H - N + 1)  # same hold, same structure
        assert oq.solver_name == "osqp"
        out = oq.solve(x0, ref, d)
        assert out.feasible and out.status == "solved"
        q, low, high = vectors(qp, x0, ref, d)
        P, A, x, y = 2.0 * qp.Hhalf, qp.Acon, out.U, out.dual
        Ax = A @ x
        z = np.clip(Ax, low, high)
        eps = p.eps
        assert np.max(np.abs(Ax - z)) <= eps + eps * max(np.max(np.abs(Ax)), np.max(np.abs(z)))
        eps_dual = eps + eps * max(np.max(np.abs(P @ x)), np.max(np.abs(A.T @ y)),
                                   np.max(np.abs(q)))
        assert np.max(np.abs(P @ x + q + A.T @ y)) <= eps_dual
        mu = np.linalg.eigvalsh(P).min()
        assert np.linalg.norm(x - res.U) <= np.sqrt(len(x)) * eps_dual / mu


def test_hot_and_cold_daqp_starts_agree():
    """The hot start (active set of the previous dual) changes the path, not the answer."""
    _, calls = record(TubeStopMpc, 10)
    hot_iters = cold_iters = 0
    for qp, x0, ref, d, _, res in calls:
        cold = qp.solve(x0, ref, d)
        q, low, high = vectors(qp, x0, ref, d)
        _, _, tol = kkt_reference(qp, q, low, high, res.dual)
        np.testing.assert_allclose(res.U, cold.U, rtol=0, atol=2 * tol)
        hot_iters += res.iterations
        cold_iters += cold.iterations
    assert hot_iters <= cold_iters


def integrator_qp(solver: str, max_iter: int) -> HorizonQP:
    """x+ = x + du over 5 stages, x <= 0.5 at every stage: tracking 2 hits all 5 bounds."""
    H = 5
    return HorizonQP(np.eye(1), np.ones(1), np.zeros(1), H, range(H), np.eye(1), 0.01,
                     np.eye(1), F=np.eye(1), ref_mask=np.zeros(1), lo=np.full((H + 1, 1), -10.0),
                     hi=np.full((H + 1, 1), 0.5), du_min=-1.0, du_max=1.0,
                     max_iter=max_iter, solver=solver)


@pytest.mark.parametrize("solver", ["daqp", "osqp"])
def test_unfinished_solves_are_not_feasible(solver):
    """An iteration limit (OSQP: 'maximum iterations reached' / 'solved inaccurate'; DAQP:
    exit flag -4) is never taken as a solution; with enough iterations the same QP solves."""
    x0, ref = np.zeros(1), np.full((6, 1), 2.0)
    done = integrator_qp(solver, 10000).solve(x0, ref)
    assert done.feasible and done.status == "solved"
    np.testing.assert_allclose(done.states[1:, 0], 0.5, atol=1e-5)  # OSQP: within eps
    cut = integrator_qp(solver, 1).solve(x0, ref)
    assert not cut.feasible and cut.status != "solved"
    assert np.all(np.isnan(cut.U)) and cut.cost == np.inf


def test_qp_solver_is_checked():
    with pytest.raises(ValueError, match="qp_solver"):
        TubeStopMpc(replace(StopMpcParams(), qp_solver="cvxopt"))
