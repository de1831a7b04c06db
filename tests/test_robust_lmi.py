"""Kothare LMI robust MPC (controllers/common/lmi.py, seed 003 eqs. 22-26)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg as sl

from controllers.common.lmi import KothareLmi

T = 1.0
B0 = 0.333


def tracking_vertex(a: float) -> tuple[np.ndarray, np.ndarray]:
    """Speed error (km/h) and position error (m) of the seed 003 design model."""
    return np.array([[a, 0.0], [T / 3.6, 1.0]]), np.array([[B0], [0.0]])


VERTICES = [tracking_vertex(a) for a in (0.9998, 0.9989, 0.9976)]


@pytest.mark.parametrize("x", [[2.0, -15.0], [-8.0, 40.0], [0.3, 0.0]])
def test_solution_satisfies_every_vertex_lmi_and_the_input_bound(x):
    u_max = 2.0
    lmi = KothareLmi(2, 1, len(VERTICES), np.eye(2), np.eye(1), u_max=[u_max])
    sol = lmi.solve(np.array(x), VERTICES)
    assert sol.ok, sol.status
    tol = lmi.tolerance
    mats = lmi.vertex_matrices(sol, VERTICES)
    for M in mats:
        # interior-point feasibility: each LMI holds to the solver's relative tolerance of
        # the matrix's size (a few orders above rounding)
        assert np.linalg.eigvalsh(M).min() >= -10 * tol * np.abs(M).max()
    # eq. 23 to within delta: [1 x'; x Qv] + delta I >= 0, so x'(Qv + delta I)^-1 x <= 1 + delta
    delta = 10 * tol * np.abs(mats[0]).max()
    # eq. 25: max over the invariant ellipsoid of |F z| is sqrt(Y Qv^-1 Y') <= u_max
    peak = float(np.sqrt((sol.Y @ np.linalg.solve(sol.Qv, sol.Y.T))[0, 0]))
    assert peak <= u_max * (1 + 10 * tol)
    # the ellipsoid holds x (eq. 23) and is invariant at every vertex under u = F x
    Pinv = np.linalg.inv(sol.Qv + delta * np.eye(2))
    z = np.array(x, float)
    assert z @ Pinv @ z <= 1 + delta
    for A, B in VERTICES:
        zk = z.copy()
        for _ in range(50):
            zk = (A + B @ sol.F) @ zk
            assert zk @ Pinv @ zk <= 1 + delta
            assert abs(float((sol.F @ zk)[0])) <= u_max * (1 + 10 * tol)


@pytest.mark.parametrize("a", [0.9998, 0.9976])
def test_single_vertex_unconstrained_is_lq_feedback(a):
    """One vertex, no input LMI: the min of x'Px over the Riccati inequality is the DARE
    solution and the applied input F x is the LQ input -K x (Kothare 1996, section 3.1)."""
    A, B = tracking_vertex(a)
    Q1, R = np.diag([1.0, 1.0]), np.eye(1)
    lmi = KothareLmi(2, 1, 1, Q1, R)
    P = sl.solve_discrete_are(A, B, Q1, R)
    K = np.linalg.solve(R + B.T @ P @ B, B.T @ P @ A)
    for x in ([1.0, -3.0], [-4.0, 25.0]):
        x = np.array(x)
        sol = lmi.solve(x, [(A, B)])
        assert sol.ok
        g_star = float(x @ P @ x)
        # gamma is the optimal value x'P*x to the solver's relative gap tolerance
        assert abs(sol.gamma - g_star) <= 10 * lmi.tolerance * g_star
        # for any feasible (P, F): x'Qx + u'Ru + (Ax+Bu)'P*(Ax+Bu) <= gamma with u = F x, and
        # the left side is x'P*x + (u - u*)'(R + B'P*B)(u - u*): so the input error is
        # bounded by sqrt((gamma - x'P*x) / (R + B'P*B)); gap and feasibility ~ tol * gamma
        u, u_star = float((sol.F @ x)[0]), float((-K @ x)[0])
        bound = np.sqrt(10 * lmi.tolerance * g_star / float((R + B.T @ P @ B)[0, 0]))
        assert abs(u - u_star) <= bound


def test_problem_is_built_once_and_reused():
    lmi = KothareLmi(2, 1, len(VERTICES), np.eye(2), np.eye(1), u_max=[2.0])
    assert lmi.problem.is_dpp()
    first = lmi.solve(np.array([1.0, 2.0]), VERTICES)
    again = lmi.solve(np.array([1.0, 2.0]), VERTICES)
    other = lmi.solve(np.array([-5.0, 30.0]), VERTICES[::-1])
    assert first.ok and again.ok and other.ok
    np.testing.assert_allclose(first.F, again.F, rtol=1e-6)
    assert not np.allclose(first.F, other.F, rtol=1e-3)


def test_wrong_vertex_count_and_solver_are_rejected():
    with pytest.raises(ValueError, match="solver"):
        KothareLmi(2, 1, 1, np.eye(2), np.eye(1), solver="mosek")
    lmi = KothareLmi(2, 1, 2, np.eye(2), np.eye(1))
    with pytest.raises(ValueError, match="built for 2"):
        lmi.solve(np.zeros(2), VERTICES)


def test_an_event_the_first_solver_leaves_unsolved_is_solved_by_the_fallback(monkeypatch):
    """Clarabel stopping short of its tolerance ("optimal_inaccurate") hands the event to SCS:
    the solution is marked as the fallback's and satisfies every LMI to SCS's tolerance;
    without a fallback the event stays unsolved; a fallback equal to the solver is refused."""
    with pytest.raises(ValueError, match="fallback"):
        KothareLmi(2, 1, 1, np.eye(2), np.eye(1), fallback="clarabel")
    x = np.array([2.0, -15.0])
    alone = KothareLmi(2, 1, len(VERTICES), np.eye(2), np.eye(1), u_max=[2.0])
    lmi = KothareLmi(2, 1, len(VERTICES), np.eye(2), np.eye(1), u_max=[2.0], fallback="scs")
    for problem in (alone, lmi):
        real = problem._solve_with

        def stalls(solver, real=real):
            return "optimal_inaccurate" if solver == "clarabel" else real(solver)

        monkeypatch.setattr(problem, "_solve_with", stalls)
        monkeypatch.setattr(problem, "_solve_direct", lambda x, v: ("optimal_inaccurate", None))
    assert not alone.solve(x, VERTICES).ok
    sol = lmi.solve(x, VERTICES)
    assert sol.ok and sol.fallback, sol.status
    tol = 1e-4  # SCS's eps_abs / eps_rel (KothareLmi.solver_options)
    for M in lmi.vertex_matrices(sol, VERTICES):
        assert np.linalg.eigvalsh(M).min() >= -10 * tol * np.abs(M).max()


def test_direct_clarabel_path_gives_cvxpys_solution():
    """Clarabel on the conic data (direct) and through ``problem.solve`` get the same data and
    settings: F and gamma agree to Clarabel's relative tolerance of their magnitude."""
    rng = np.random.default_rng(3)
    for _ in range(3):
        verts = [(A + 0.005 * rng.standard_normal((2, 2)), B) for A, B in VERTICES]
        direct = KothareLmi(2, 1, len(verts), np.eye(2), np.eye(1), u_max=[2.0])
        plain = KothareLmi(2, 1, len(verts), np.eye(2), np.eye(1), u_max=[2.0], direct=False)
        assert direct.direct and not plain.direct
        for _ in range(3):
            x = rng.standard_normal(2) * [5.0, 40.0]
            a, b = direct.solve(x, verts), plain.solve(x, verts)
            assert a.status == b.status
            if not a.ok:
                continue
            tol = 10 * direct.tolerance
            assert abs(a.gamma - b.gamma) <= tol * abs(b.gamma)
            assert np.max(np.abs(a.F - b.F)) <= tol * max(1.0, np.max(np.abs(b.F)))


def test_status_names_are_cvxpys():
    """The direct path names a solved event as cvxpy does without importing it."""
    import cvxpy as cp
    from cvxpy.reductions.solvers.conic_solvers.clarabel_conif import CLARABEL

    from controllers.common.lmi import CLARABEL_SOLVED, OPTIMAL

    assert OPTIMAL == cp.OPTIMAL
    assert CLARABEL.STATUS_MAP[CLARABEL_SOLVED] == cp.OPTIMAL


_FRESH_PROCESS = """
import sys
import numpy as np
from controllers.common.lmi import KothareLmi
A = [(np.array([[0.9, 0.0], [0.25, 1.0]]), np.array([[b], [0.0]])) for b in (0.4, 0.6)]
lmi = KothareLmi(2, 1, 2, np.eye(2), np.eye(1), u_max=[2.0])
sol = lmi.solve(np.array([1.0, -3.0]), A)
print(sol.status, "cvxpy" in sys.modules, *(float(f).hex() for f in sol.F.ravel()))
"""


def test_cached_direct_data_solves_without_cvxpy_and_gives_the_same_gain(tmp_path):
    """A process that finds the direct path's data on disk solves without importing cvxpy,
    and gets the gain of the process that built the data, bit for bit."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    env = {**os.environ, "ATO_COSIM_CACHE": str(tmp_path),
           "PYTHONPATH": str(Path(__file__).resolve().parents[1])}
    runs = [subprocess.run([sys.executable, "-c", _FRESH_PROCESS], env=env, check=True,
                           capture_output=True, text=True).stdout.split() for _ in range(2)]
    (status0, imported0, *gain0), (status1, imported1, *gain1) = runs
    assert status0 == status1 == "optimal"
    assert imported0 == "True" and imported1 == "False"
    assert gain0 == gain1
