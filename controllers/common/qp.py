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
vectors ``q``, ``l``, ``u`` are updated. Two solvers, chosen per QP (``solver``):

* ``"daqp"`` (default): DAQP's dual active-set method, set up once (its workspace keeps the
  factorisation) and hot-started from the active set of the caller's previous dual, solving
  these small dense QPs exactly (to rounding) in a few iterations;
* ``"osqp"``: the ADMM solver, warm-started from the caller's primal and dual vectors, for
  large sparse problems (answers within its tolerance ``eps``).

Either way the warm start comes from vectors the caller keeps (so controller state, not the
solver object, decides the result), and only a fully solved QP counts as feasible (OSQP's
"solved inaccurate", DAQP's soft-optimal or iteration-limit exits do not).

:func:`support_of_sum` gives the support function of a Minkowski sum of linear images of a
polytope W (its vertices), which is all the tube tightening needs (eqs. 14, 26).
"""

from __future__ import annotations

import copy
import functools
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import ClassVar

import daqp
import numpy as np

QP_SOLVERS = ("daqp", "osqp")
_OSQP_SOLVED = "solved"
_DAQP_OPTIMAL = 1  # exitflag: 2 is soft-optimal (a relaxed constraint), < 0 failures
_DAQP_STATUS = {1: "solved", 2: "soft optimal", -1: "infeasible", -2: "cycling",
                -3: "unbounded", -4: "iteration limit", -5: "nonconvex",
                -6: "overdetermined initial active set"}
# DAQP sense bits: ACTIVE = 1, LOWER = 2. From the sign of a dual (-1, 0, +1) as int32,
# ``sign & 3`` is 3 (active at the lower bound; two's complement), 0 or 1 (active, upper)
_SENSE_MASK = 3


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
    """One solve: free moves ``U``, stage moves ``du``, status, duals; the cost and the
    predicted states are computed when first read (an RMPC event needs neither)."""

    U: np.ndarray
    du: np.ndarray
    feasible: bool
    status: str
    solve_time: float  # s, wall time of vector update + solve + U/du/dual
    dual: np.ndarray  # one per constraint row of ``Acon`` (> 0 upper, < 0 lower bound active)
    iterations: int = 0
    # (qp, q, e, ref) of the solve: e the free response's tracking error (flattened)
    _data: tuple | None = field(default=None, repr=False, compare=False)

    @functools.cached_property
    def cost(self) -> float:
        """``J = U' Hh U + q' U + e' Qblk e`` (eq. 11 / 25); inf when not feasible."""
        if not self.feasible or self._data is None:
            return math.inf
        qp, q, e, _ = self._data
        U = self.U
        return float(U @ (qp.Hhalf @ U) + q @ U + e @ (qp._Qblk @ e))

    @functools.cached_property
    def states(self) -> np.ndarray:
        """Predicted states ``(H+1, n)`` (NaN when not feasible)."""
        qp, _, e, ref_f = self._data
        if not self.feasible:
            return np.full((qp.H + 1, qp.n), np.nan)
        return (e + ref_f + qp._Gam_f @ self.U).reshape(qp.H + 1, qp.n)


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
                 du_max: float = math.inf, eps: float = 1e-7, max_iter: int = 10000,
                 solver: str = "daqp") -> None:
        if solver not in QP_SOLVERS:
            raise ValueError(f"qp_solver = {solver!r} must be one of {QP_SOLVERS}")
        self.solver_name = solver
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
        # rows: the du box first (DAQP's simple bounds), then the stage and terminal rows
        self.Acon = np.vstack([np.eye(nu)] + blocks)
        self.n_con = self.Acon.shape[0]
        self.nu = nu
        # the vector update is one product W [x0; ref; d] of the stacked rows
        #   e = Phi x0 + Psi d - ref (tracking error of the free response, flattened stages),
        #   q = Mq e, base = Fs (Phi x0 + Psi d) - Fr ref (row offsets, 0 on the du box);
        # then const = e' Qblk e
        N1 = (H + 1) * n
        Phi_f, Psi_f = Phi.reshape(N1, n), Psi.reshape(N1, H)
        self._Gam_f = Gam.reshape(N1, nu)
        Mq = 2.0 * np.hstack([Gam[i].T @ Qs[i] for i in range(H + 1)])
        Qblk = np.zeros((N1, N1))
        for i in range(H + 1):
            Qblk[i * n:(i + 1) * n, i * n:(i + 1) * n] = Qs[i]
        self._Qblk = Qblk
        Fs = np.zeros((self.n_con, N1))
        Fr = np.zeros((self.n_con, N1))
        row = nu
        for i, F_, mask_ in self._sel:
            r = F_.shape[0]
            Fs[row:row + r, i * n:(i + 1) * n] = F_
            Fr[row:row + r, i * n:(i + 1) * n] = mask_[:, None] * F_
            row += r
        err_rows = np.hstack([Phi_f, -np.eye(N1), Psi_f])
        self._W = np.vstack([err_rows, Mq @ err_rows, np.hstack([Fs @ Phi_f, -Fr, Fs @ Psi_f])])
        self._W_nod = np.ascontiguousarray(self._W[:, :n + N1])
        self._split = (N1, N1 + nu)
        self.du_lo = np.full(nu, du_min)
        self.du_hi = np.full(nu, du_max)
        self._lo_all = np.concatenate([self.du_lo] + self._lo)
        self._hi_all = np.concatenate([self.du_hi] + self._hi)
        self._nan = (np.full(nu, np.nan), np.full(H, np.nan), np.full((H + 1, n), np.nan))
        self._eps, self._max_iter = eps, int(max_iter)
        self._setup_solver()

    def _setup_solver(self) -> None:
        """A fresh solver workspace for this QP (OSQP, or DAQP with H factorised once)."""
        nu, eps, max_iter = self.nu, self._eps, self._max_iter
        if self.solver_name == "osqp":
            import osqp  # here, not at the top: with DAQP (the default) a process never
            import scipy.sparse as sp  # pays its ~0.1 s import (jinja2, scipy.sparse)

            self.solver = osqp.OSQP()
            self.solver.setup(sp.csc_matrix(np.triu(2.0 * self.Hhalf)), np.zeros(nu),
                              sp.csc_matrix(self.Acon), -np.ones(self.n_con),
                              np.ones(self.n_con), verbose=False, eps_abs=eps, eps_rel=eps,
                              max_iter=max_iter, polishing=False, warm_starting=True,
                              adaptive_rho=True, adaptive_rho_interval=25, rho=self.RHO0)
            return
        # the factorisation of H (and of the constraint rows in its metric) is done here,
        # once; a solve only updates the vectors
        self.solver = daqp.Model()
        self._cold = np.zeros(self.n_con, dtype=np.int32)
        flag = self.solver.setup(2.0 * self.Hhalf, np.zeros(nu),
                                 np.ascontiguousarray(self.Acon[nu:]),
                                 np.ones(self.n_con), -np.ones(self.n_con))
        if isinstance(flag, tuple):
            flag = flag[0]
        if flag < 0:
            raise ValueError(f"DAQP setup failed (exitflag {flag}): Hessian not positive "
                             f"definite? check r_du > 0")
        settings = self.solver.settings
        settings["iter_limit"] = max_iter
        self.solver.settings = settings

    def clone(self) -> HorizonQP:
        """The same QP (matrices shared, never written) with its own solver workspace."""
        twin = copy.copy(self)
        twin._setup_solver()
        return twin

    def predict(self, x0: np.ndarray, U: np.ndarray, d: np.ndarray | None = None) -> np.ndarray:
        """Predicted states ``(H+1, n)`` for free moves ``U``."""
        X = self.Phi @ x0 + self.Gam @ U
        if d is not None:
            X = X + self.Psi @ d
        return X

    def _failed(self, status: str, t0: float, iterations: int = 0) -> QPResult:
        U, du, _ = self._nan
        return QPResult(U.copy(), du.copy(), False, status, time.perf_counter() - t0,
                        np.zeros(self.n_con), iterations, (self, None, None, None))

    def solve(self, x0: np.ndarray, ref: np.ndarray, d: np.ndarray | None = None,
              warm_x: np.ndarray | None = None, warm_y: np.ndarray | None = None) -> QPResult:
        """Solve for the current state ``x0`` and references ``ref`` ``(H+1, n)``.

        ``solve_time`` is the wall time of the whole step: vector update, solve and result.
        """
        t0 = time.perf_counter()
        ref_f = ref.ravel()
        if d is None:
            z = self._W_nod @ np.concatenate((x0, ref_f))
        else:
            z = self._W @ np.concatenate((x0, ref_f, d))
        a, b = self._split
        err, q, base = z[:a], z[a:b], z[b:]
        low, high = self._lo_all - base, self._hi_all - base
        if (high - low).min() < -1e-12:  # tightened sets empty along the way: infeasible
            return self._failed("empty constraint set", t0)
        np.maximum(high, low, out=high)
        if self.solver_name == "daqp":
            U, dual, status, iters = self._solve_daqp(q, low, high, warm_y)
        else:
            U, dual, status, iters = self._solve_osqp(q, low, high, warm_x, warm_y)
        if U is None:
            return self._failed(status, t0, iters)
        du = self.E @ U
        return QPResult(U, du, True, status, time.perf_counter() - t0, dual, iters,
                        (self, q, err, ref_f))

    def _solve_osqp(self, q: np.ndarray, low: np.ndarray, high: np.ndarray,
                    warm_x: np.ndarray | None, warm_y: np.ndarray | None
                    ) -> tuple[np.ndarray | None, np.ndarray, str, int]:
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
        status = str(res.info.status)
        iters = int(res.info.iter)
        if status != _OSQP_SOLVED or res.x is None or not np.all(np.isfinite(res.x)):
            return None, np.zeros(self.n_con), status, iters
        return np.asarray(res.x, float), np.asarray(res.y, float), status, iters

    def _solve_daqp(self, q: np.ndarray, low: np.ndarray, high: np.ndarray,
                    warm_y: np.ndarray | None) -> tuple[np.ndarray | None, np.ndarray, str, int]:
        """Hot start from the active set of ``warm_y`` (its sign: which bound); cold if that
        fails (a stale working set can be degenerate for the new data)."""
        sense = self._cold
        if warm_y is not None and len(warm_y) == self.n_con:
            sense = np.sign(warm_y).astype(np.int32)
            sense &= _SENSE_MASK
        iters = 0
        while True:
            self.solver.update(f=q, bupper=high, blower=low, sense=sense)
            x, _, flag, info = self.solver.solve()
            iters += int(info["iterations"])
            if flag == _DAQP_OPTIMAL or sense is self._cold:
                break
            sense = self._cold
        status = _DAQP_STATUS.get(int(flag), f"exitflag {flag}")
        if flag != _DAQP_OPTIMAL or not np.all(np.isfinite(x)):
            return None, np.zeros(self.n_con), status, iters
        return x, info["lam"], status, iters


class DenseQP:
    """``min 1/2 x'Hx + q'x  s.t.  l <= C x <= u`` with a fixed constraint matrix ``C`` and a
    dense Hessian whose values change between solves (adaptive models, e.g. seed 001's
    ISMPC, whose ``Theta`` follows the estimated pseudo-Jacobian).

    Solved by DAQP (a dual active-set method, exact up to round-off, about 0.1 ms for 30
    variables), warm-started from the duals of the caller's previous plan. Unlike OSQP after
    a Hessian update, DAQP keeps no state between calls, so the result depends only on the
    data and the warm start the caller keeps (FMU state save/restore reproduces it)."""

    def __init__(self, n: int, C: np.ndarray | None = None) -> None:
        """``C = None``: bounds on ``x`` only (DAQP's simple bounds, cheaper than rows)."""
        self.n = int(n)
        C = np.zeros((0, self.n)) if C is None else C
        self.C = np.ascontiguousarray(np.atleast_2d(np.asarray(C, float)))
        self.n_con = self.C.shape[0] or self.n
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
