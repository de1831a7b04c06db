"""An independent optimum of the optimal-train-control model: a convex program over position.

Variables on a position grid ``x_0 .. x_N`` (steps of at most ``ds``, the grade and speed-limit
changes as nodes): the kinetic energy per unit effective mass ``E_k = v_k^2 / 2`` at the nodes
and, on each step, constant traction ``f_k``, regenerative braking ``b_k`` and friction
braking ``q_k`` (per unit effective mass, m/s2). With the force constant over a step the
acceleration is constant, so ``E`` is linear in ``s`` and the step's time is exactly
``2 h / (v_k + v_{k+1})``, which is convex in ``(E_k, E_{k+1})`` (the inverse of a sum of
concave square roots).

    minimise   sum h_k (f_k / eta_t - eta_r b_k)
    subject to E_{k+1} - E_k = h_k (f_k - b_k - q_k - r(E_mid) - g_k),   E_0 = E_N = 0,
               sum 2 h_k / (sqrt(2 E_k) + sqrt(2 E_{k+1})) <= T,   E_k <= V_lim^2 / 2,
               f_k <= F_t / m_eff,  f_k <= P_t / (m_eff v_mid),  b_k <= F_r / m_eff,
               b_k <= P_r / (m_eff v_mid),  q_k <= F_f / m_eff,  -d_max <= dE/ds <= a_max

with ``E_mid = (E_k + E_{k+1}) / 2``. Davis' ``c v^2 = 2 c E`` and ``a`` are linear in ``E``;
the ``b v = b sqrt(2 E)`` term and the power limits ``P / (m v)`` are not (concave and convex
in ``E``). They are replaced by their first-order expansions at the previous solution (a
sequential convex program; the power limits' expansion is a tangent below a convex function,
an inner approximation) and the program is solved again until the speeds stop changing: at a
fixed point the expansions are exact and the fixed point satisfies the original problem's KKT
conditions. Solved with cvxpy and Clarabel.

This shares nothing with :mod:`cosim.optimal.pontryagin` but the train and line data: no
regimes, no multiplier, no cost-to-go.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cvxpy as cp
import numpy as np

from cosim.optimal.model import Section, Train


@dataclass(frozen=True)
class OracleRun:
    s: np.ndarray  # m, nodes (line positions)
    v: np.ndarray  # m/s
    energy: float  # J: traction work / eta_t - eta_r regenerative work
    running_time: float  # s
    iterations: int


def _grid(section: Section, ds: float) -> np.ndarray:
    knots = np.concatenate(([0.0], section.breakpoints(), [section.length]))
    out = [np.array([0.0])]
    for a, b in zip(knots[:-1], knots[1:]):
        n = max(int(math.ceil((b - a) / ds - 1e-9)), 1)
        out.append(np.linspace(a, b, n + 1)[1:])
    return np.concatenate(out)


def solve(section: Section, train: Train, running_time: float, ds: float,
          max_iter: int = 30, vtol: float = 1e-6) -> OracleRun:
    """The discretised optimum on a grid of at most ``ds`` (m) (module text)."""
    x = _grid(section, ds)
    h = np.diff(x)
    n = h.size
    m = train.effective_mass
    g = np.asarray(train.grade_accel(section.w_on(x[:-1], x[1:])), dtype=float)
    lim = section.limit_on(x[:-1], x[1:], train)
    node_cap = 0.5 * np.minimum(np.r_[lim[0], lim], np.r_[lim, lim[-1]]) ** 2
    d = train.davis
    E = cp.Variable(n + 1, nonneg=True)
    f = cp.Variable(n, nonneg=True)
    b = cp.Variable(n, nonneg=True)
    q = cp.Variable(n, nonneg=True)
    # first-order expansions at the previous mid-step speed vbar: b v ~ b (vbar + (E - Ebar)
    # / vbar) and P / (m v) ~ P / (m vbar) - P (E - Ebar) / (m vbar^3)
    vbar = cp.Parameter(n, pos=True)
    inv_vbar = cp.Parameter(n, pos=True)
    inv_vbar3 = cp.Parameter(n, pos=True)
    emid = 0.5 * (E[:-1] + E[1:])
    e_bar = cp.Parameter(n, nonneg=True)
    speed_lin = vbar + cp.multiply(emid - e_bar, inv_vbar)
    resist = (d.a + d.b * speed_lin + 2.0 * d.c * emid) / m
    cons = [E[0] == 0, E[n] == 0, E <= node_cap,
            E[1:] - E[:-1] == cp.multiply(h, f - b - q - resist - g),
            f <= train.max_traction_force / m,
            f <= train.max_traction_power / m * (inv_vbar - cp.multiply(emid - e_bar,
                                                                        inv_vbar3)),
            b <= train.max_regen_force / m,
            b <= train.max_regen_power / m * (inv_vbar - cp.multiply(emid - e_bar, inv_vbar3)),
            q <= train.max_friction_force / m]
    # no traction above the train's top speed: the limits already keep v <= max_speed
    if math.isfinite(train.max_accel):
        cons.append(E[1:] - E[:-1] <= h * train.max_accel)
    if math.isfinite(train.max_decel):
        cons.append(E[1:] - E[:-1] >= -h * train.max_decel)
    sq = cp.sqrt(2.0 * E)
    step_time = 2.0 * cp.multiply(h, cp.inv_pos(sq[:-1] + sq[1:]))
    cons.append(cp.sum(step_time) <= running_time)
    cost = cp.sum(cp.multiply(h, f / train.traction_efficiency - train.regen_efficiency * b))
    prob = cp.Problem(cp.Minimize(cost), cons)
    # start: a constant mid speed of distance over time
    vm = np.full(n, section.length / running_time)
    it = 0
    for it in range(1, max_iter + 1):
        vm = np.maximum(vm, 1.0)  # expansions about at least 1 m/s (starts and stops)
        vbar.value, inv_vbar.value, inv_vbar3.value = vm, 1.0 / vm, 1.0 / vm**3
        e_bar.value = 0.5 * vm**2
        prob.solve(solver=cp.CLARABEL)
        if prob.status not in ("optimal", "optimal_inaccurate"):
            raise RuntimeError(f"oracle: {prob.status} at iteration {it}")
        Ev = np.maximum(E.value, 0.0)
        new = np.sqrt(Ev[:-1] + Ev[1:])  # sqrt(2 E_mid)
        done = np.max(np.abs(new - vm)) <= vtol * max(1.0, float(new.max()))
        vm = new
        if done:
            break
    Ev = np.maximum(E.value, 0.0)
    v = np.sqrt(2.0 * Ev)
    # the energy and time of the solution on the exact model of the grid: forces from the
    # kinematics with the exact b v term at the solution's mid speeds
    vmid = np.sqrt(Ev[:-1] + Ev[1:])
    net = np.diff(Ev) / h + train.resistance(vmid) + g
    regen = np.minimum(np.maximum(-net, 0.0), train.regen_limit(vmid))
    energy = m * float(np.sum(h * (np.maximum(net, 0.0) / train.traction_efficiency
                                   - train.regen_efficiency * regen)))
    vs = v[:-1] + v[1:]
    return OracleRun(x + section.start, v, energy, float(np.sum(2.0 * h / vs)), it)
