"""The one QP/horizon builder for predictive controllers: condensed horizon, cost, constraints.

Prediction over ``H`` stages of ``x+ = A x + b du + g d`` (``d`` a known scalar disturbance per
stage, e.g. a fed-forward resistance)::

    X = Phi x0 + Gamma U + Psi d,   du_i = (E U)_i   (E: move blocking, held stages have du = 0)

Cost (eq. 11 / eq. 25)::

    J = sum_{i<H} c_i ||x_i - r_i||_Q^2 + sum_{i<H} c'_i R du_i^2 + ||x_H - r_H||_P^2

with per-stage scale factors ``c_i`` (the 1/beta of eq. 25). Constraints ``lo_i <= F (x_i -
ref_mask * r_i) <= hi_i`` on stages 1..H (stage 0 is the measured state, nothing to decide)
and a terminal box on stage H, plus ``du_min <= du <= du_max`` on the free moves.
The Hessian and constraint matrix are fixed for a given structure; between solves only the
vectors ``q``, ``l``, ``u`` are updated, and OSQP is warm-started from vectors the caller keeps
(so controller state, not the solver object, decides the result).

:func:`support_of_sum` gives the support function of a Minkowski sum of linear images of a
polytope W (its vertices), which is all the tube tightening needs (eqs. 14, 26).
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import ClassVar

import numpy as np
import osqp
import scipy.sparse as sp

_SOLVED = ("solved", "solved inaccurate")


def support_of_sum(mats: Sequence[np.ndarray], w_vertices: np.ndarray,
                   rows: np.ndarray) -> np.ndarray:
    """``h(f) = max_{z in (+)_j M_j W} f'z = sum_j max_v f' M_j v`` for each row f of ``rows``."""
    rows = np.atleast_2d(rows)
    total = np.zeros(rows.shape[0])
    for m in mats:
        total += np.max(rows @ m @ w_vertices.T, axis=1)
    return total


@dataclass
class QPResult:
    """One solve: free moves ``U``, stage moves ``du``, predicted states, cost, status."""

    U: np.ndarray
    du: np.ndarray
    states: np.ndarray  # (H+1, n)
    cost: float
    feasible: bool
    status: str
    solve_time: float  # s, wall time of update + solve
    dual: np.ndarray


class HorizonQP:
    """Condensed QP over a horizon with move blocking, built once, solved many times."""

    RHO0: ClassVar[float] = 0.1  # OSQP step size at the start of every solve

    def __init__(self, A: np.ndarray, b: np.ndarray, g: np.ndarray, horizon: int,
                 free_stages: Sequence[int], Q: np.ndarray, R: float, P: np.ndarray,
                 stage_scale: Sequence[float] | None = None,
                 F: np.ndarray | None = None, ref_mask: np.ndarray | None = None,
                 lo: np.ndarray | None = None, hi: np.ndarray | None = None,
                 F_term: np.ndarray | None = None, lo_term: np.ndarray | None = None,
                 hi_term: np.ndarray | None = None, du_min: float = -math.inf,
                 du_max: float = math.inf, eps: float = 1e-7, max_iter: int = 10000) -> None:
        n, H = A.shape[0], int(horizon)
        if H < 1:
            raise ValueError(f"horizon = {horizon} must be >= 1")
        free = sorted(set(int(i) for i in free_stages))
        if not free or free[0] != 0 or free[-1] >= H:
            raise ValueError(f"free_stages {free_stages} must start at 0 and lie in [0, {H})")
        self.n, self.H, self.free = n, H, free
        nu = len(free)
        E = np.zeros((H, nu))
        for j, i in enumerate(free):
            E[i, j] = 1.0
        self.E = E
        # condensed prediction
        Phi = np.zeros((H + 1, n, n))
        Gam = np.zeros((H + 1, n, nu))
        Psi = np.zeros((H + 1, n, H))
        Phi[0] = np.eye(n)
        for i in range(H):
            Phi[i + 1] = A @ Phi[i]
            Gam[i + 1] = A @ Gam[i] + np.outer(b, E[i])
            Psi[i + 1] = A @ Psi[i]
            Psi[i + 1][:, i] += g
        self.Phi, self.Gam, self.Psi = Phi, Gam, Psi
        scale = np.ones(H) if stage_scale is None else np.asarray(stage_scale, float)
        Qs = [scale[i] * Q for i in range(H)] + [P]
        self.Qbar = Qs
        Hq = np.zeros((nu, nu))
        for i in range(H + 1):
            Hq += Gam[i].T @ Qs[i] @ Gam[i]
        Rbar = np.diag(scale * R)
        Hq += E.T @ Rbar @ E
        self.Hhalf = 0.5 * (Hq + Hq.T)
        # constraints
        blocks, self._lo, self._hi, self._sel = [], [], [], []
        if F is not None:
            F = np.atleast_2d(F)
            mask = np.ones(F.shape[0]) if ref_mask is None else np.asarray(ref_mask, float)
            for i in range(1, H + 1):
                blocks.append(F @ Gam[i])
                self._sel.append((i, F, mask))
                self._lo.append(np.asarray(lo[i], float))
                self._hi.append(np.asarray(hi[i], float))
        if F_term is not None:
            F_term = np.atleast_2d(F_term)
            blocks.append(F_term @ Gam[H])
            self._sel.append((H, F_term, np.ones(F_term.shape[0])))
            self._lo.append(np.asarray(lo_term, float))
            self._hi.append(np.asarray(hi_term, float))
        blocks.append(np.eye(nu))
        self.Acon = np.vstack(blocks)
        # vector updates as single products: q = Mq err, const = err' Qblk err, and the
        # constraint offsets base = Fs x_free - Fr ref (flattened stages)
        self._Qstack = np.array(Qs)
        self._Mq = 2.0 * np.hstack([Gam[i].T @ Qs[i] for i in range(H + 1)])
        n_rows = sum(F_.shape[0] for _, F_, _ in self._sel)
        Fs = np.zeros((n_rows, (H + 1) * n))
        Fr = np.zeros((n_rows, (H + 1) * n))
        row = 0
        for i, F_, mask_ in self._sel:
            r = F_.shape[0]
            Fs[row:row + r, i * n:(i + 1) * n] = F_
            Fr[row:row + r, i * n:(i + 1) * n] = mask_[:, None] * F_
            row += r
        self._Fs, self._Fr = Fs, Fr
        self.du_lo = np.full(nu, du_min)
        self.du_hi = np.full(nu, du_max)
        self._lo_all = np.concatenate(self._lo + [self.du_lo])
        self._hi_all = np.concatenate(self._hi + [self.du_hi])
        self.n_con = self.Acon.shape[0]
        self.solver = osqp.OSQP()
        self.solver.setup(sp.csc_matrix(np.triu(2.0 * self.Hhalf)), np.zeros(nu),
                          sp.csc_matrix(self.Acon), -np.ones(self.n_con), np.ones(self.n_con),
                          verbose=False, eps_abs=eps, eps_rel=eps, max_iter=max_iter,
                          polishing=False, warm_starting=True, adaptive_rho=True,
                          adaptive_rho_interval=25, rho=self.RHO0)
        self.nu = nu

    def predict(self, x0: np.ndarray, U: np.ndarray, d: np.ndarray | None = None) -> np.ndarray:
        """Predicted states ``(H+1, n)`` for free moves ``U``."""
        X = self.Phi @ x0 + self.Gam @ U
        if d is not None:
            X = X + self.Psi @ d
        return X

    def solve(self, x0: np.ndarray, ref: np.ndarray, d: np.ndarray | None = None,
              warm_x: np.ndarray | None = None, warm_y: np.ndarray | None = None) -> QPResult:
        """Solve for the current state ``x0`` and references ``ref`` ``(H+1, n)``."""
        t0 = time.perf_counter()
        free_part = self.Phi @ x0  # (H+1, n)
        if d is not None:
            free_part = free_part + self.Psi @ d
        err = free_part - ref
        q = self._Mq @ err.ravel()
        const = float(np.einsum("ij,ijk,ik->", err, self._Qstack, err))
        base = np.concatenate([self._Fs @ free_part.ravel() - self._Fr @ ref.ravel(),
                               np.zeros(self.nu)])
        low, high = self._lo_all - base, self._hi_all - base
        nan = np.full(self.nu, np.nan)
        if np.any(low > high + 1e-12):  # tightened sets empty along the way: infeasible
            return QPResult(nan, np.full(self.H, np.nan), np.full((self.H + 1, self.n), np.nan),
                            math.inf, False, "empty constraint set",
                            time.perf_counter() - t0, np.zeros(self.n_con))
        high = np.maximum(high, low)
        self.solver.update(q=q, l=low, u=high)
        # rho adapts within a solve (every 25 iterations, not by timing) and restarts from
        # RHO0 at every solve, so the result depends only on the data and the warm start
        self.solver.update_settings(rho=self.RHO0)
        if warm_x is not None and warm_y is not None and len(warm_x) == self.nu \
                and len(warm_y) == self.n_con:
            self.solver.warm_start(x=np.asarray(warm_x, float), y=np.asarray(warm_y, float))
        else:
            self.solver.warm_start(x=np.zeros(self.nu), y=np.zeros(self.n_con))
        res = self.solver.solve(raise_error=False)
        elapsed = time.perf_counter() - t0
        status = str(res.info.status)
        if status not in _SOLVED or res.x is None or not np.all(np.isfinite(res.x)):
            return QPResult(nan, np.full(self.H, np.nan), np.full((self.H + 1, self.n), np.nan),
                            math.inf, False, status, elapsed, np.zeros(self.n_con))
        U = np.asarray(res.x, float)
        cost = float(U @ self.Hhalf @ U + q @ U + const)
        return QPResult(U, self.E @ U, self.predict(x0, U, d), cost, True, status, elapsed,
                        np.asarray(res.y, float))



class DenseQP:
    """``min 1/2 x'Hx + q'x  s.t.  l <= C x <= u`` with a fixed constraint matrix ``C`` and a
    dense Hessian whose values change between solves (adaptive models, e.g. seed 001's
    ISMPC, whose ``Theta`` follows the estimated pseudo-Jacobian).

    Solved by DAQP (a dual active-set method, exact up to round-off, about 0.1 ms for 30
    variables), warm-started from the duals of the caller's previous plan. Unlike OSQP after
    a Hessian update, DAQP keeps no state between calls, so the result depends only on the
    data and the warm start the caller keeps (FMU state save/restore reproduces it)."""

    def __init__(self, n: int, C: np.ndarray) -> None:
        self.n = int(n)
        self.C = np.ascontiguousarray(np.atleast_2d(np.asarray(C, float)))
        self.n_con = self.C.shape[0]
        self._sense = np.zeros(self.n_con, dtype=np.int32)

    def solve(self, H: np.ndarray, q: np.ndarray, lo: np.ndarray, hi: np.ndarray,
              warm_dual: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, str]:
        """Solution ``x``, constraint duals and status; ``x`` is NaN on failure."""
        import daqp

        kwargs = {}
        if warm_dual is not None and len(warm_dual) == self.n_con:
            kwargs["dual_start"] = np.ascontiguousarray(warm_dual, dtype=float)
        x, _, flag, info = daqp.solve(np.ascontiguousarray(H, dtype=float),
                                      np.ascontiguousarray(q, dtype=float), self.C,
                                      np.ascontiguousarray(np.maximum(hi, lo), dtype=float),
                                      np.ascontiguousarray(lo, dtype=float), self._sense,
                                      **kwargs)
        x = np.asarray(x, float)
        if flag < 1 or not np.all(np.isfinite(x)):
            return np.full(self.n, np.nan), np.zeros(self.n_con), f"daqp exitflag {flag}"
        return x, np.asarray(info["lam"], float), "solved"
