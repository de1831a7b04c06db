"""Design model (eq. 9-10, exact ZOH) and the shared horizon QP builder."""

from __future__ import annotations

import math

import numpy as np
import pytest

from controllers.common.design_model import (
    A_C,
    U_PREV,
    S,
    V,
    brake_delay_model,
    delay_samples,
    zoh,
)
from controllers.common.qp import HorizonQP, support_of_sum
from cosim.fmu.state import to_ticks
from plants.brake_delay import BrakeDelayParams, BrakeDelayTrain
from plants.resistance import Davis
from plants.route import Route

EPS = np.finfo(float).eps


def zoh_tolerance(a: np.ndarray, T: float) -> float:
    """Relative accuracy of ``expm`` on the augmented matrix [[A, B], [0, 0]] T: backward error
    u ||M||_1 (Al-Mohy & Higham 2009) plus the 2n + 4 roundings of the block products."""
    n = a.shape[0] + 1
    return (np.linalg.norm(a, 1) * T + 2 * n + 4) * EPS / 2


def test_zoh_first_order_lag_and_double_integrator():
    tau, T = 0.4, 0.2
    a = np.array([[-1 / tau]])
    ad, bd = zoh(a, np.array([[1 / tau]]), T)
    tol = zoh_tolerance(a, T)
    assert ad[0, 0] == pytest.approx(math.exp(-T / tau), rel=tol)
    assert bd[0, 0] == pytest.approx(1 - math.exp(-T / tau), rel=tol)
    a = np.array([[0.0, 0.0], [1.0, 0.0]])
    ad, bd = zoh(a, np.array([1.0, 0.0]), T)
    tol = zoh_tolerance(a, T)
    np.testing.assert_allclose(ad, [[1, 0], [T, 1]], rtol=tol, atol=tol)
    np.testing.assert_allclose(bd[:, 0], [T, T * T / 2], rtol=tol)


def test_zoh_rejects_bad_shapes_and_step():
    with pytest.raises(ValueError):
        zoh(np.eye(2), np.ones(3), 0.2)
    with pytest.raises(ValueError):
        zoh(np.eye(2), np.ones(2), 0.0)


def test_delay_must_be_whole_samples():
    assert delay_samples(1.0, 0.2) == 5
    with pytest.raises(ValueError, match="whole number"):
        delay_samples(0.5, 0.2)


@pytest.mark.parametrize("resistance_n", [0.0, 49e3])
def test_design_model_matches_plant_discrete_response(resistance_n):
    """Random piecewise-constant commands through the dead time: the design model (with the
    resistance as a known constant a_r) reproduces the plant samples."""
    p = BrakeDelayParams(davis=Davis(resistance_n, 0.0, 0.0), max_step=0.01)
    plant = BrakeDelayTrain(p, Route.flat(), v0=30.0)
    m = brake_delay_model(p.brake_gain, p.brake_time_constant, p.brake_delay, 0.2)
    a_r = resistance_n / p.mass
    rng = np.random.default_rng(3)
    commands = rng.uniform(0.0, 60.0, size=60)
    lag = m.delay_steps
    x = np.array([0.0, 0.0, 30.0, 0.0])
    worst = 0.0
    for k, u in enumerate(commands):
        plant.advance(to_ticks(0.2 * k), to_ticks(0.2), {"brake_command": float(u)})
        applied = commands[k - lag] if k >= lag else 0.0
        x = m.step_command(x, applied, a_r)
        y = plant.outputs()
        worst = max(worst, abs(y["a_c"] - x[0]), abs(y["v"] - x[V]), abs(y["s"] - x[S]))
        # u_prev + (u - u_prev): two roundings of commands <= 60 %
        assert x[U_PREV] == pytest.approx(applied, abs=2 * EPS * 60.0)
    assert worst < 1e-8


def _random_qp(rng, horizon=6):
    m = brake_delay_model(0.0107, 0.4, 1.0, 0.2)
    Q = np.diag([0.0, 0.0, 10.0, 5.0])
    P = np.eye(4)
    return m, HorizonQP(m.A, m.b, m.g, horizon, range(horizon), Q, 0.01, P), Q, P


def test_unconstrained_qp_equals_least_squares():
    rng = np.random.default_rng(0)
    m, qp, Q, P = _random_qp(rng)
    x0 = np.array([-0.3, 40.0, 15.0, 100.0])
    ref = np.column_stack([np.full(7, -0.5), np.full(7, 46.7), 15 - 0.1 * np.arange(7),
                           100 + 3 * np.arange(7)])
    res = qp.solve(x0, ref)
    assert res.feasible
    # normal equations of the same cost, built independently by brute force
    H = 6
    def cost(U):
        x, J = x0.copy(), 0.0
        for i in range(H):
            e = x - ref[i]
            J += e @ Q @ e + 0.01 * U[i] ** 2
            x = m.step(x, U[i])
        e = x - ref[H]
        return J + e @ P @ e
    base = cost(np.zeros(H))
    grad = np.array([(cost(np.eye(H)[j]) - cost(-np.eye(H)[j])) / 2 for j in range(H)])
    hess = np.array([[(cost(np.eye(H)[i] + np.eye(H)[j]) - cost(np.eye(H)[i])
                       - cost(np.eye(H)[j]) + base) for j in range(H)] for i in range(H)])
    U = np.linalg.solve(hess, -grad)
    np.testing.assert_allclose(res.U, U, rtol=1e-4, atol=1e-4)
    assert res.cost == pytest.approx(cost(res.U), rel=1e-9)


def test_qp_reports_empty_constraint_set_without_raising():
    m = brake_delay_model(0.0107, 0.4, 1.0, 0.2)
    F = np.array([[0.0, 0.0, 1.0, 0.0]])
    lo = np.full((4, 1), 1.0)
    hi = np.full((4, 1), 0.0)  # lo > hi: empty
    qp = HorizonQP(m.A, m.b, m.g, 3, [0, 1, 2], np.eye(4), 1.0, np.eye(4), F=F, lo=lo, hi=hi)
    res = qp.solve(np.zeros(4), np.zeros((4, 4)))
    assert not res.feasible and math.isinf(res.cost)


def test_support_of_sum_of_segment():
    w = np.array([[0.0, -1.0], [0.0, 2.0]])
    rows = np.array([[0.0, 1.0], [0.0, -1.0]])
    np.testing.assert_allclose(support_of_sum([np.eye(2), 2 * np.eye(2)], w, rows), [6.0, 3.0])


def test_euler_rows_are_the_papers_eq9():
    T = 0.2
    exact = brake_delay_model(0.0107, 0.4, 1.0, T)
    euler = brake_delay_model(0.0107, 0.4, 1.0, T, euler=True)
    np.testing.assert_array_equal(euler.A[[A_C, U_PREV]], exact.A[[A_C, U_PREV]])  # lag exact
    np.testing.assert_array_equal(euler.A[V], [T, 0.0, 1.0, 0.0])
    np.testing.assert_array_equal(euler.A[S], [0.0, 0.0, T, 1.0])
    assert euler.b[V] == euler.b[S] == 0.0 and euler.g[V] == -T and euler.g[S] == 0.0
