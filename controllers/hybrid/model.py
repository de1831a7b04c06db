"""Control model of the multi-mass CRH3 for hybrid MPC (seed 004, eqs. 1-8 and 13).

State ``x = [v_1 .. v_n, x_1 .. x_n]`` (speeds m/s, displacements m, front to rear), input
``u = [u_1 .. u_n]`` in kN (traction > 0, braking < 0), sample time ``Ts``. Every car obeys
(eq. 1-3)::

    m_i dv_i/dt = u_i - m_i w(v) - F_i + F_(i-1),   F_j = k (x_j - x_j+1) + d (v_j - v_j+1)

The couplers (spring k and damper d, the plant's values) are discretised exactly (zero-order
hold, :func:`controllers.common.design_model.zoh`); the resistance per unit mass ``w`` is the
three-segment piecewise-affine law of eq. 4, ``w = alpha_j + beta_j v``, held over the sample.
The segment ``j`` is chosen by the mass-weighted mean speed ``v = c'x`` (one segment for the
whole train: with couplers this stiff the cars' speeds differ by millimetres per second, so
this replaces eq. 4's per-car segment at an error of ``m_i beta (v_i - v)``, a few newtons,
and needs one set of binaries per stage instead of one per car). This gives the PWA system of
eq. 5::

    x+ = A_j x + B u + f_j,   A_j = A0 + beta_j g c',   f_j = alpha_j g

(``g``: the response to a deceleration of 1 m/s^2 on every car). :class:`PwlResistance.fit`
fits ``w`` to the plant's Davis curve (least squares of a *continuous* three-segment line on
0 .. v_fit over equal-width segments), so eq. 4's table is continuous at the breakpoints.

MLD form (eq. 13; Bemporad and Morari's big-M translation of the PWA system and the mode
logic). Per stage the decision vector is ``w = [u (n), delta, b (K), z (K)]`` (K = 2
breakpoints ``v_k``)::

    x+ = A_1 x + B u + g (alpha_1 + sum_k dbeta_k z_k)
    b_k = [c'x >= v_k],   z_k = b_k (c'x - v_k)        (6 rows per breakpoint, big-M,
                                                          and the valid cut z_k >= c'x - v_k)
    delta = 1 (traction):  0 <= u_i <= T_i,  delta = 0 (braking): -B_i <= u_i <= 0
                           (row u_i - U delta in [-U, 0]; trailers have T_i = 0)

so a trailer's force is zero whenever the train pulls (the paper's point of delta). Coupler
forces (``|F_j| <= F_max``, 1000 kN) and speeds (``v_i <= v_max``) are linear state
constraints (eq. 7-8). The three controllers share one :class:`ChainModel`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from controllers.common.design_model import zoh

KN = 1e3  # N per kN: inputs and coupler forces of the control model are in kN


@dataclass(frozen=True)
class PwlResistance:
    """Continuous piecewise-affine running resistance per unit mass ``w(v)`` (m/s^2), eq. 4."""

    breakpoints: tuple[float, ...]  # interior breakpoints v_k (m/s), increasing
    alpha: tuple[float, ...]  # m/s^2, per segment
    beta: tuple[float, ...]  # 1/s, per segment

    @classmethod
    def fit(cls, davis_a: float, davis_b: float, davis_c: float, mass: float, v_fit: float,
            segments: int = 3, points: int = 2001) -> PwlResistance:
        """Least-squares continuous fit of ``(a + b v + c v^2) / mass`` on ``[0, v_fit]``
        with ``segments`` equal-width segments (breakpoints at ``k v_fit / segments``)."""
        if segments < 1 or not v_fit > 0 or not mass > 0:
            raise ValueError(f"fit: segments = {segments}, v_fit = {v_fit}, mass = {mass} "
                             "must be positive")
        bps = [v_fit * k / segments for k in range(1, segments)]
        v = np.linspace(0.0, v_fit, points)
        w = (davis_a + davis_b * v + davis_c * v * v) / mass
        basis = np.column_stack([np.ones_like(v), v] + [np.maximum(v - vk, 0.0) for vk in bps])
        coef = np.linalg.lstsq(basis, w, rcond=None)[0]
        alpha, beta = [coef[0]], [coef[1]]
        for k, vk in enumerate(bps):
            beta.append(beta[-1] + coef[2 + k])
            alpha.append(alpha[-1] - coef[2 + k] * vk)
        return cls(tuple(float(x) for x in bps), tuple(float(x) for x in alpha),
                   tuple(float(x) for x in beta))

    @property
    def dbeta(self) -> np.ndarray:
        """Slope changes at the breakpoints (1/s)."""
        return np.diff(np.asarray(self.beta))

    def segment(self, v: float) -> int:
        """Index j of the segment holding ``v`` (a breakpoint belongs to the upper one)."""
        return int(np.searchsorted(self.breakpoints, v, side="right"))

    def __call__(self, v: float) -> float:
        j = self.segment(v)
        return self.alpha[j] + self.beta[j] * v


@dataclass(frozen=True)
class Limits:
    """Per-event limits: envelope per car (kN, >= 0), coupler force (kN), speed (m/s)."""

    traction: np.ndarray
    brake: np.ndarray
    coupler: float = 1000.0
    speed: float = 350.0 / 3.6


class ChainModel:
    """The n-car chain at sample time ``Ts`` in PWA (eq. 5) and MLD (eq. 13) form."""

    def __init__(self, masses: Sequence[float], stiffness: float, damping: float,
                 resistance: PwlResistance, sample_time: float = 1.0,
                 motored: Sequence[bool] | None = None, force_bound: float = 1000.0,
                 speed_range: tuple[float, float] = (-10.0, 100.0)) -> None:
        m = np.asarray(masses, float)
        n = m.size
        if n < 1 or np.any(m <= 0):
            raise ValueError(f"masses = {masses} must be positive")
        if not speed_range[0] < 0 <= max(resistance.breakpoints, default=0.0) < speed_range[1]:
            raise ValueError(f"speed_range = {speed_range} must contain 0 and the breakpoints")
        self.n, self.m, self.Ts = n, m, float(sample_time)
        self.k, self.d = float(stiffness), float(damping)
        self.res = resistance
        self.motored = np.ones(n, bool) if motored is None else np.asarray(motored, bool)
        self.U = float(force_bound)  # kN, big-M of the delta rows (above every envelope)
        self.v_lo, self.v_hi = map(float, speed_range)  # bounds of c'x for the big-M rows
        lap = np.zeros((n, n))
        for j in range(n - 1):
            lap[j, j] += 1
            lap[j + 1, j + 1] += 1
            lap[j, j + 1] -= 1
            lap[j + 1, j] -= 1
        minv = np.diag(1.0 / m)
        ac = np.block([[-self.d * minv @ lap, -self.k * minv @ lap],
                       [np.eye(n), np.zeros((n, n))]])
        bc = np.vstack([KN * minv, np.zeros((n, n))])
        gc = np.concatenate([-np.ones(n), np.zeros(n)])  # -1 m/s^2 on every car
        A0, bd = zoh(ac, np.column_stack([bc, gc]), self.Ts)
        self.A0, self.B, self.g = A0, bd[:, :n], bd[:, n]
        self.c = np.concatenate([m / m.sum(), np.zeros(n)])  # mean speed c'x
        # coupler force rows (kN): F_j = k (x_j - x_j+1) + d (v_j - v_j+1)
        cf = np.zeros((n - 1, 2 * n))
        for j in range(n - 1):
            cf[j, j], cf[j, j + 1] = self.d / KN, -self.d / KN
            cf[j, n + j], cf[j, n + j + 1] = self.k / KN, -self.k / KN
        self.coupler_rows = cf
        self.K = len(resistance.breakpoints)
        self.nw = n + 1 + 2 * self.K  # per-stage decision vector [u, delta, b, z]
        self.A1 = self.A_seg(0)
        self.Bw = np.zeros((2 * n, self.nw))  # x+ = A1 x + Bw w + f1
        self.Bw[:, :n] = self.B
        self.Bw[:, n + 1 + self.K:] = np.outer(self.g, resistance.dbeta)
        self.f1 = resistance.alpha[0] * self.g

    # -- indices of the per-stage decision vector
    @property
    def i_delta(self) -> int:
        return self.n

    def i_b(self, k: int) -> int:
        return self.n + 1 + k

    def i_z(self, k: int) -> int:
        return self.n + 1 + self.K + k

    # -- PWA (eq. 5)
    def A_seg(self, j: int) -> np.ndarray:
        return self.A0 + self.res.beta[j] * np.outer(self.g, self.c)

    def pwa_step(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """x+ of eq. 5: the segment of the mean speed, forces ``u`` in kN."""
        j = self.res.segment(float(self.c @ x))
        return self.A_seg(j) @ x + self.B @ u + self.res.alpha[j] * self.g

    # -- MLD (eq. 13)
    def mld_step(self, x: np.ndarray, w: np.ndarray) -> np.ndarray:
        return self.A1 @ x + self.Bw @ w + self.f1

    def aux(self, x: np.ndarray, u: np.ndarray, delta: int) -> np.ndarray:
        """The decision vector ``w`` the mode logic implies at state ``x``."""
        v = float(self.c @ x)
        b = np.array([1.0 if v >= vk else 0.0 for vk in self.res.breakpoints])
        z = b * (v - np.asarray(self.res.breakpoints))
        return np.concatenate([u, [float(delta)], b, z])

    def mld_rows(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(Ex, Ew, lo, hi)``: the mixed-integer rows ``lo <= Ex x + Ew w <= hi`` of a stage."""
        n, nw = self.n, self.nw
        ex, ew, lo, hi = [], [], [], []

        def row(xc: np.ndarray | None, wc: dict[int, float], low: float, high: float) -> None:
            ex.append(np.zeros(2 * n) if xc is None else xc)
            r = np.zeros(nw)
            for i, value in wc.items():
                r[i] = value
            ew.append(r)
            lo.append(low)
            hi.append(high)

        for i in range(n):  # u_i <= U delta, u_i >= -U (1 - delta)
            row(None, {i: 1.0, self.i_delta: -self.U}, -self.U, 0.0)
        inf = math.inf
        for k, vk in enumerate(self.res.breakpoints):
            big, small = self.v_hi - vk, self.v_lo - vk  # M > 0 > m
            b, z = self.i_b(k), self.i_z(k)
            row(None, {z: 1.0, b: -big}, -inf, 0.0)  # z <= M b
            row(None, {z: 1.0, b: -small}, 0.0, inf)  # z >= m b
            row(-self.c, {z: 1.0, b: -small}, -inf, -vk - small)  # z <= v - vk - m (1 - b)
            row(-self.c, {z: 1.0, b: -big}, -vk - big, inf)  # z >= v - vk - M (1 - b)
            row(self.c, {b: -big}, -inf, vk)  # b = 0 -> v <= vk
            row(self.c, {b: -small}, vk + small, inf)  # b = 1 -> v >= vk
            # valid cut z >= max(0, v - vk) (z >= 0 is a simple bound): the relaxation then
            # never sees less resistance than the convex w, so few branches are needed
            row(-self.c, {z: 1.0}, -vk, inf)
        return np.array(ex), np.array(ew), np.array(lo), np.array(hi)

    def input_bounds(self, lim: Limits) -> tuple[np.ndarray, np.ndarray]:
        """Simple bounds of ``w`` (the binaries free in [0, 1])."""
        bps = np.asarray(self.res.breakpoints)
        trac = np.where(self.motored, np.asarray(lim.traction, float), 0.0)
        lo = np.concatenate([-np.asarray(lim.brake, float), [0.0], np.zeros(self.K),
                             np.zeros(self.K)])
        hi = np.concatenate([trac, [1.0], np.ones(self.K), np.maximum(0.0, self.v_hi - bps)])
        return lo, hi

    def state_rows(self, lim: Limits) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(F, lo, hi)``: coupler forces and car speeds, ``lo <= F x <= hi`` (eq. 8)."""
        n = self.n
        sp = np.hstack([np.eye(n), np.zeros((n, n))])
        F = np.vstack([self.coupler_rows, sp])
        lo = np.concatenate([np.full(n - 1, -lim.coupler), np.full(n, -math.inf)])
        hi = np.concatenate([np.full(n - 1, lim.coupler), np.full(n, lim.speed)])
        return F, lo, hi

    def mld_feasible(self, x: np.ndarray, w: np.ndarray, lim: Limits, tol: float = 1e-9) -> bool:
        """Do ``x`` and ``w`` satisfy the stage's mixed-integer rows and bounds?"""
        ex, ew, lo, hi = self.mld_rows()
        r = ex @ x + ew @ w
        blo, bhi = self.input_bounds(lim)
        return bool(np.all(r >= lo - tol) and np.all(r <= hi + tol)
                    and np.all(w >= blo - tol) and np.all(w <= bhi + tol))

    def coupler_forces(self, x: np.ndarray) -> np.ndarray:
        return self.coupler_rows @ x
