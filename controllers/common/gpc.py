"""Generalised predictive control (GPC) on an incremental MIMO ARX model identified on line by
recursive least squares with forgetting: the GPC baseline of seed 001 (Ny = 3, Nu = 2,
forgetting 0.9) and of seed 003.

Model (CARIMA in increments, so the controller has integral action and a constant load or
offset gives no steady error)::

    dy(t) = sum_{i=1..na} A_i dy(t-i) + sum_{j=1..nb} B_j du(t-j)          (n outputs, m inputs)

RLS with forgetting ``f`` on the regressor ``x = [dy(t-1); ...; du(t-1); ...]``, one shared
covariance ``P`` for all outputs::

    K = P x / (f + x'P x),   Theta += (dy - Theta x) K',   P = (P - K x'P) / f

With ``f < 1`` and little excitation (cruising) ``P`` grows without bound ("blow-up"); its
trace is capped at ``p_max``. No update while ``||x|| <= excitation``.

Control: the model's predictions over ``Ny`` samples are affine in the moves
``dU = [du(t); ...; du(t+Nu-1)]`` (moves after ``Nu`` are zero): ``Y = f + G dU``. The cost
``||Y - R||^2 + w ||dU||^2`` gives ``dU = (G'G + w I)^-1 G'(R - f)``; the first move is applied
and the input clipped to the caller's box (the clipped input is what the model remembers).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cosim.fmu.declare import Checked, param
from cosim.fmu.state import StatefulCore


@dataclass(frozen=True)
class GpcParams(Checked):
    """GPC horizons and weight, ARX orders and RLS settings."""

    Ny: int = param(3, "1", "prediction horizon N_y (samples)", min=1, max=100,
                   integer=True)
    Nu: int = param(2, "1", "control horizon N_u (samples)", min=1, max=100,
                   integer=True)
    forgetting: float = param(0.9, "1", "forgetting factor of the recursive least squares",
                              min=0.5, max=1.0)
    control_weight: float = param(0.1, "1", "weight w of ||dU||^2 against ||Y - R||^2",
                                  min=0.0)
    na: int = param(1, "1", "order of the output polynomial (increments)", min=1, max=10,
                    integer=True)
    nb: int = param(1, "1", "order of the input polynomial (increments)", min=1, max=10,
                    integer=True)
    b_init: float = param(0.5, "1", "diagonal of B_1 at the start", min=0.0)
    a_init: float = param(0.0, "1", "diagonal of A_1 at the start (A_2.. = 0)")
    p0: float = param(100.0, "1", "initial covariance P = p0 I", min=1e-9)
    p_max: float = param(1e4, "1", "largest trace of P (bound under forgetting)", min=1e-9)
    excitation: float = param(1e-9, "1", "no update while ||regressor|| is at most this",
                              min=0.0)

    def check_relations(self) -> None:
        if self.Nu > self.Ny:
            raise ValueError(f"Nu = {self.Nu} must be <= Ny = {self.Ny}")


class Gpc(StatefulCore):
    """MIMO GPC with RLS. Per sample: :meth:`observe` ``y(t)``, then :meth:`control`."""

    state_fields = ("theta", "P", "y_prev", "dy_hist", "du_hist", "u_prev", "started",
                    "updates")

    def __init__(self, params: GpcParams, n_out: int, n_in: int | None = None) -> None:
        params.check()
        self.p = params
        self.n = n_out
        self.m = n_out if n_in is None else n_in
        n, m = self.n, self.m
        self.n_reg = n * params.na + m * params.nb
        theta = np.zeros((n, self.n_reg))
        theta[:, :n] = params.a_init * np.eye(n)
        theta[:, n * params.na:n * params.na + m] = params.b_init * np.eye(n, m)
        self.theta = theta
        self.P = params.p0 * np.eye(self.n_reg)
        self.y_prev = np.zeros(n)
        self.dy_hist = np.zeros((params.na, n))  # dy(t), dy(t-1)... newest first
        self.du_hist = np.zeros((params.nb, m))  # du(t-1), du(t-2)... newest first
        self.u_prev = np.zeros(m)
        self.started = False
        self.updates = 0

    def regressor(self) -> np.ndarray:
        return np.concatenate([self.dy_hist.ravel(), self.du_hist.ravel()])

    def observe(self, y: np.ndarray, adapt: bool = True) -> None:
        """New measurement ``y(t)``: one RLS step on ``dy(t)``."""
        y = np.asarray(y, float)
        if not self.started:
            self.y_prev = y
            self.started = True
            return
        p = self.p
        dy = y - self.y_prev
        self.y_prev = y
        x = self.regressor()  # dy(t-1)..., du(t-1)...
        if adapt and float(np.linalg.norm(x)) > p.excitation:
            Px = self.P @ x
            k = Px / (p.forgetting + float(x @ Px))
            self.theta = self.theta + np.outer(dy - self.theta @ x, k)
            P = (self.P - np.outer(k, Px)) / p.forgetting
            P = 0.5 * (P + P.T)
            trace = float(np.trace(P))
            if trace > p.p_max:
                P *= p.p_max / trace
            self.P = P
            self.updates += 1
        self.dy_hist = np.vstack([dy, self.dy_hist[:-1]])

    def _simulate(self, moves: np.ndarray) -> np.ndarray:
        """Predicted outputs ``y(t+1..t+Ny)`` (Ny, n) for future moves (Ny, m)."""
        p, n = self.p, self.n
        A = self.theta[:, :n * p.na]
        B = self.theta[:, n * p.na:]
        dy_hist, du_hist = self.dy_hist.copy(), self.du_hist.copy()
        y = self.y_prev.copy()
        out = np.empty((p.Ny, n))
        for j in range(p.Ny):
            du_hist = np.vstack([moves[j], du_hist[:-1]])
            dy = A @ dy_hist.ravel() + B @ du_hist.ravel()
            dy_hist = np.vstack([dy, dy_hist[:-1]])
            y = y + dy
            out[j] = y
        return out

    def prediction_matrices(self) -> tuple[np.ndarray, np.ndarray]:
        """Free response ``f`` (Ny n,) and step-response matrix ``G`` (Ny n, Nu m)."""
        p, m = self.p, self.m
        zero = np.zeros((p.Ny, m))
        f = self._simulate(zero).ravel()
        G = np.empty((p.Ny * self.n, p.Nu * m))
        for k in range(p.Nu):
            for j in range(m):
                moves = zero.copy()
                moves[k, j] = 1.0
                G[:, k * m + j] = self._simulate(moves).ravel() - f
        return f, G

    def plan(self, refs: np.ndarray) -> np.ndarray:
        """The unclipped input ``u(t) = u(t-1) + du(t)``, ``du(t)`` the first move of the
        minimiser ``dU = (G'G + w I)^-1 G'(R - f)`` (nothing is recorded)."""
        f, G = self.prediction_matrices()
        H = G.T @ G + self.p.control_weight * np.eye(G.shape[1])
        dU = np.linalg.solve(H, G.T @ (np.asarray(refs, float).ravel() - f))
        return self.u_prev + dU[:self.m]

    def input_gain(self) -> np.ndarray:
        """``B_1`` (n, m): the model's response of ``dy(t+1)`` to ``du(t)``."""
        n = self.n * self.p.na
        return self.theta[:, n:n + self.m]

    def control(self, refs: np.ndarray, lo: np.ndarray | None = None,
                hi: np.ndarray | None = None) -> np.ndarray:
        """Input ``u(t)`` for references ``refs`` (Ny, n) of ``y(t+1..t+Ny)``, clipped to
        ``[lo, hi]`` and remembered as applied."""
        u = self.plan(refs)
        if lo is not None:
            u = np.maximum(u, lo)
        if hi is not None:
            u = np.minimum(u, hi)
        self.applied(u)
        return u

    def applied(self, u: np.ndarray) -> None:
        """Record the input ``u(t)`` actually applied."""
        u = np.asarray(u, float)
        self.du_hist = np.vstack([u - self.u_prev, self.du_hist[:-1]])
        self.u_prev = u
