"""The MIQP of hybrid MPC (seed 004, eqs. 14-15) over the MLD model, with move blocking (eq. 17).

Decision vector ``V``: the inputs of each block of stages (``blocks``, e.g. 3:4:3; all ones is
the plain GMPC of eq. 15), then per stage ``s = 0..N-1`` the mode ``delta_s``, the segment
binaries ``b_s`` and the products ``z_s`` of :class:`controllers.hybrid.model.ChainModel`.
Condensed prediction ``X = Phi x0 + Gam V + f`` (stages 1..N) and cost::

    J = sum_{s=1..N} ||x_s - r_s||_Q^2 + sum_{s=0..N-1} ||u_s||_R^2 + ||u_s - u_{s-1}||_dR^2

(``u`` in kN: eq. 10's traction/brake energy weight R; eq. 9's tracking weight Q on all speeds
and displacements; eq. 11's weight dR on the force increments, ``u_{-1}`` the input applied
last). Eq. 15 writes the same problem in the increments ``dU``; ``U = u_{-1} + T dU`` (``T``
lower triangular of ones) is an invertible affine map, so both forms have one minimiser and
the one here, in ``U``, keeps the move blocks and mode bounds as simple bounds.
Rows: the MLD rows of every stage (big-M, mode) and the state rows of
stages 1..N (coupler force, speed limit). The matrices are fixed; per event only the bounds
and the linear term change.

Binaries (DAQP ``sense`` BINARY, branch and bound inside its dual active-set QP, Arnstrom et
al.): ``delta_s`` is fixed by the caller's schedule (the paper fixes delta) or left free;
``b_0``, ``z_0`` follow from the measured state; ``b_s`` is fixed wherever the mean speed
cannot reach the breakpoint within ``s`` samples at the largest acceleration/deceleration the
envelope allows (a valid bound: ``c'x+ = c'x + Ts (sum u / M - w)`` exactly), else binary.
The binaries carry a regularisation ``eps (b - b_guess)^2`` (guess: the segment of the
reference speed at that stage; 1 for delta) and ``z`` a tiny ``eps z^2``, so that the Hessian
is positive definite (DAQP needs it) and the relaxation leans to the likely integer point;
with ``eps = 1e-6`` this changes the cost by at most ``eps`` per binary and ``eps * 70^2`` per
product, against costs of 1e1..1e4: the MIQP solved (and certified optimal) is the
regularised one, which :meth:`HybridMiqp.solve_enumerated` enumerates too.
"""

from __future__ import annotations

import itertools
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass

import daqp
import numpy as np

from controllers.hybrid.model import ChainModel, Limits

_BINARY = 16
_EQUALITY = 5  # ACTIVE | IMMUTABLE with lower == upper
_INF = 1e30
# retries of a failed solve; the last, a looser primal tolerance (1e-5 kN or m/s on rows of
# O(1..100)), turned a spurious "infeasible" of the MB-MPC (t = 623 s, 9 free binaries) into
# a solve in 2 ms instead of 1.3 s of enumeration
_RETRY_SETTINGS: tuple[dict, ...] = ({}, {"cycle_tol": 100}, {"pivot_tol": 1e-6},
                                     {"primal_tol": 1e-8}, {"primal_tol": 1e-5})
ENUMERATE_MAX_FREE = 10  # last resort after the retries: every binary assignment as a QP
EPS_REG = 1e-6


def split_blocks(blocks: Sequence[int], delta: Sequence[int | None]) -> list[int]:
    """``blocks`` cut wherever the fixed mode changes between two stages of one block.

    A block holds one input vector; a traction stage needs it >= 0 and a braking stage <= 0,
    so a block spanning both could only apply 0. Cut at the change, each stage keeps its mode
    (``delta[s]`` None, a free mode, never cuts: the MIQP picks it)."""
    out: list[int] = []
    s = 0
    for length in blocks:
        start = s
        for t in range(s + 1, s + length):
            a = delta[t - 1] if t - 1 < len(delta) else None
            b = delta[t] if t < len(delta) else None
            if a is not None and b is not None and a != b:
                out.append(t - start)
                start = t
        s += length
        out.append(s - start)
    return out


def parse_blocks(text: str, horizon: int) -> list[int]:
    """Block lengths from ``"3:4:3"`` (or ``""``: every stage its own move); they sum to N."""
    if not text.strip():
        return [1] * horizon
    try:
        blocks = [int(x) for x in text.replace(",", ":").split(":")]
    except ValueError:
        raise ValueError(f"move_blocks = {text!r}: expected lengths like '3:4:3'") from None
    if any(b < 1 for b in blocks) or sum(blocks) != horizon:
        raise ValueError(f"move_blocks = {text!r}: positive lengths summing to N = {horizon}")
    return blocks


@dataclass
class MiqpResult:
    """One solve: first input (kN), all stage inputs, predicted states, cost, status."""

    u0: np.ndarray
    V: np.ndarray
    states: np.ndarray  # (N + 1, 2n)
    cost: float
    feasible: bool
    status: str
    solve_time: float  # s, wall time of the whole event (bounds, setup, branch and bound)
    nodes: int = 0
    cpu_time: float = 0.0  # s, CPU time of this thread for the same (immune to a busy machine)
    free_binaries: int = 0
    stage_w: np.ndarray | None = None  # (N, nw): [u, delta, b, z] of every stage
    blocks: tuple[int, ...] = ()  # the blocking of the problem solved (split at mode changes)


class HybridMiqp:
    """The condensed MIQP of eq. 15 for one model, horizon and blocking; built once."""

    def __init__(self, model: ChainModel, horizon: int, q: Sequence[float] | float,
                 r: Sequence[float] | float, blocks: Sequence[int] | None = None,
                 dr: Sequence[float] | float = 0.0) -> None:
        md = model
        n, N, nw, K = md.n, int(horizon), md.nw, md.K
        blocks = [1] * N if blocks is None else [int(b) for b in blocks]
        if N < 1 or sum(blocks) != N or any(b < 1 for b in blocks):
            raise ValueError(f"blocks {blocks} must be positive and sum to N = {N}")
        self.md, self.N, self.blocks = md, N, blocks
        self._weights = (q, r)
        self._dr = dr
        self._split: dict[tuple[int, ...], HybridMiqp] = {}
        nb = len(blocks)
        self.nV = nV = n * nb + N * (1 + 2 * K)
        # stage vectors w_s = P_s V
        P = np.zeros((N, nw, nV))
        stage_block = np.repeat(np.arange(nb), blocks)
        for s in range(N):
            j = stage_block[s]
            P[s, :n, n * j:n * (j + 1)] = np.eye(n)
            base = n * nb + s * (1 + 2 * K)
            P[s, n:, base:base + 1 + 2 * K] = np.eye(1 + 2 * K)
        self.P = P
        # prediction x_s = Phi_s x0 + Gam_s V + f_s, s = 0..N
        Phi = np.zeros((N + 1, 2 * n, 2 * n))
        Gam = np.zeros((N + 1, 2 * n, nV))
        f = np.zeros((N + 1, 2 * n))
        Phi[0] = np.eye(2 * n)
        for s in range(N):
            Phi[s + 1] = md.A1 @ Phi[s]
            Gam[s + 1] = md.A1 @ Gam[s] + md.Bw @ P[s]
            f[s + 1] = md.A1 @ f[s] + md.f1
        self.Phi, self.Gam, self.f = Phi, Gam, f
        Q = np.diag(np.broadcast_to(np.asarray(q, float), (2 * n,)))
        R = np.diag(np.broadcast_to(np.asarray(r, float), (n,)))
        self.Q, self.R = Q, R
        H = np.zeros((nV, nV))
        for s in range(1, N + 1):
            H += Gam[s].T @ Q @ Gam[s]
        dR = np.diag(np.broadcast_to(np.asarray(dr, float), (n,)))
        self.dR = dR
        for s in range(N):
            Pu = P[s, :n]
            H += Pu.T @ R @ Pu
            D = Pu - (P[s - 1, :n] if s > 0 else 0.0)  # u_s - u_{s-1} = D V (- u_{-1} at s = 0)
            H += D.T @ dR @ D
        H = 2.0 * H  # DAQP: 1/2 V'HV + f'V
        self.binary_idx: list[tuple[int, int, int]] = []  # (V index, stage, kind: -1 delta, k)
        for s in range(N):
            base = n * nb + s * (1 + 2 * K)
            self.binary_idx.append((base, s, -1))
            for k in range(K):
                self.binary_idx.append((base + 1 + k, s, k))
                H[base + 1 + K + k, base + 1 + K + k] += 2.0 * EPS_REG
        for i, _, _ in self.binary_idx:
            H[i, i] += 2.0 * EPS_REG
        self.H = 0.5 * (H + H.T)
        # linear term: 2 sum_s Gam_s' Q (Phi_s x0 + f_s - r_s)
        self._Gq = np.stack([2.0 * Gam[s].T @ Q for s in range(N + 1)])  # (N+1, nV, 2n)
        # rows
        ex, ew, mlo, mhi = md.mld_rows()
        self._mld = (ex, ew, mlo, mhi)
        rows, self._row_x = [], []  # row coefficients on V; their dependence on x_s (stage)
        for s in range(N):
            rows.append(ex @ Gam[s] + ew @ P[s])
            self._row_x.append((s, ex, len(mlo)))
        Fst, _, _ = md.state_rows(Limits(np.zeros(n), np.zeros(n)))
        for s in range(1, N + 1):
            rows.append(Fst @ Gam[s])
            self._row_x.append((s, Fst, Fst.shape[0]))
        self.A = np.ascontiguousarray(np.vstack(rows))
        self.n_rows = self.A.shape[0]
        # DAQP collects its binary constraints at setup: every delta and b is declared binary
        # here once; a solve fixes some of them by equal bounds (branching on those is trivial)
        self._sense0 = np.zeros(nV + self.n_rows, dtype=np.int32)
        self._lo0 = np.full(nV + self.n_rows, -_INF)
        self._hi0 = np.full(nV + self.n_rows, _INF)
        for i, _, _ in self.binary_idx:
            self._sense0[i] = _BINARY
            self._lo0[i], self._hi0[i] = 0.0, 1.0
        self._nb = nb

    def _setup(self) -> daqp.Model:
        solver = daqp.Model()
        flag = solver.setup(self.H, np.zeros(self.nV), self.A, self._hi0.copy(),
                            self._lo0.copy(), self._sense0.copy())
        if isinstance(flag, tuple):
            flag = flag[0]
        if flag < 0:
            raise ValueError(f"DAQP setup failed (exitflag {flag})")
        return solver

    # -- one event -----------------------------------------------------------------------------
    def stage_states_free(self, x0: np.ndarray) -> np.ndarray:
        """Free response ``Phi_s x0 + f_s`` (s = 0..N)."""
        return self.Phi @ x0 + self.f

    def bounds(self, x0: np.ndarray, lim: Limits, delta: Sequence[int | None]
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
        """(lower, upper, sense, free binaries) for state ``x0``, limits and mode schedule
        (``delta[s]`` 0/1 fixes stage s, None leaves it to the optimiser)."""
        md, n, N, K = self.md, self.md.n, self.N, self.md.K
        nV = self.nV
        lo = np.empty(nV + self.n_rows)
        hi = np.empty(nV + self.n_rows)
        sense = np.zeros(nV + self.n_rows, dtype=np.int32)
        wlo, whi = md.input_bounds(lim)
        # a fixed delta goes into the input bounds (0 <= u <= T or -B <= u <= 0, intersected
        # over a block: solve() first cuts the blocks at mode changes) and its rows are
        # dropped: duplicate active constraints made DAQP cycle
        stage_block = np.repeat(np.arange(self._nb), self.blocks)
        ulo = np.tile(wlo[:n], (self._nb, 1))
        uhi = np.tile(whi[:n], (self._nb, 1))
        for s in range(N):
            d = delta[s] if s < len(delta) else None
            if d == 1:
                ulo[stage_block[s]] = np.maximum(ulo[stage_block[s]], 0.0)
            elif d == 0:
                uhi[stage_block[s]] = np.minimum(uhi[stage_block[s]], 0.0)
        lo[:n * self._nb] = ulo.ravel()
        hi[:n * self._nb] = np.maximum(uhi, ulo).ravel()
        free_x = self.stage_states_free(x0)
        v0 = float(md.c @ x0)
        bps = np.asarray(md.res.breakpoints)
        M = md.m.sum()
        w_min = min(md.res(md.v_lo), md.res(0.0))
        w_max = md.res(md.v_hi)
        a_up = md.Ts * (1e3 * float(np.sum(np.where(md.motored, lim.traction, 0.0))) / M - w_min)
        a_dn = md.Ts * (1e3 * float(np.sum(lim.brake)) / M + w_max)
        free = 0
        fixed_b: dict[tuple[int, int], float] = {}
        for s in range(N):
            base = n * self._nb + s * (1 + 2 * K)
            lo[base + 1:base + 1 + 2 * K] = wlo[n + 1:]
            hi[base + 1:base + 1 + 2 * K] = whi[n + 1:]
            d = delta[s] if s < len(delta) else None
            if d is None:
                lo[base], hi[base], sense[base] = 0.0, 1.0, _BINARY
                free += 1
            else:
                lo[base] = hi[base] = float(d)
                sense[base] = _BINARY
            vmin, vmax = v0 - s * a_dn, v0 + s * a_up
            for k, vk in enumerate(bps):
                ib, iz = base + 1 + k, base + 1 + K + k
                if s == 0 or vmax < vk or vmin >= vk:
                    b = 1.0 if (v0 >= vk if s == 0 else vmin >= vk) else 0.0
                    fixed_b[s, k] = b
                    lo[ib] = hi[ib] = b
                    sense[ib] = _BINARY
                    if s == 0:
                        lo[iz] = hi[iz] = b * (v0 - vk)
                    elif b == 0.0:
                        lo[iz] = hi[iz] = 0.0
                    else:  # z = v - vk by one equality row below
                        lo[iz], hi[iz] = -_INF, _INF
                else:
                    lo[ib], hi[ib], sense[ib] = 0.0, 1.0, _BINARY
                    free += 1
        row = nV
        ex, ew, mlo, mhi = self._mld
        _, Fst_lo, Fst_hi = md.state_rows(lim)
        for s, E, r in self._row_x:
            offset = E @ free_x[s]
            if E is ex:
                rlo, rhi = mlo - offset, mhi - offset
                if s >= len(delta) or delta[s] is not None:  # the delta rows come first
                    rlo[:n], rhi[:n] = -_INF, _INF
                for k in range(K):
                    b = fixed_b.get((s, k))
                    if b is None:
                        continue
                    # a fixed b leaves only z's definition: its other rows are implied by the
                    # reachable speeds, and duplicate active rows make DAQP's active set cycle
                    # or report a feasible problem infeasible (seen at t = 597 s and 621 s)
                    r0 = n + 7 * k
                    keep_hi = rhi[r0 + 2]
                    rlo[r0:r0 + 7], rhi[r0:r0 + 7] = -_INF, _INF
                    if b == 1.0 and s > 0:  # row 3: z - v - m b = -vk - m
                        rlo[r0 + 2] = rhi[r0 + 2] = keep_hi
                lo[row:row + r] = np.maximum(rlo, -_INF)
                hi[row:row + r] = np.minimum(rhi, _INF)
            else:
                lo[row:row + r] = np.maximum(Fst_lo - offset, -_INF)
                hi[row:row + r] = np.minimum(Fst_hi - offset, _INF)
            row += r
        # presolve: a row side no point of the variable box can violate is dropped (exact;
        # the coupler-force and speed rows of seed 004 never bind, and fewer near-parallel
        # rows leave DAQP fewer chances of a degenerate pivot)
        vlo, vhi = lo[:nV], hi[:nV]
        Ap, An = np.maximum(self.A, 0.0), np.minimum(self.A, 0.0)
        row_max = Ap @ vhi + An @ vlo
        row_min = Ap @ vlo + An @ vhi
        rlo, rhi = lo[nV:], hi[nV:]
        rlo[row_min >= rlo] = -_INF
        rhi[row_max <= rhi] = _INF
        return lo, hi, sense, free

    def linear_term(self, x0: np.ndarray, ref: np.ndarray, u_prev: np.ndarray | None = None
                    ) -> tuple[np.ndarray, float]:
        """``(f, const)``: linear term and constant of the cost for ``ref`` (N+1, 2n) and the
        last applied input ``u_prev`` (kN; eq. 11's first increment, zero when None)."""
        e = self.stage_states_free(x0) - ref
        f = np.einsum("svx,sx->v", self._Gq[1:], e[1:])
        up = np.zeros(self.md.n) if u_prev is None else np.asarray(u_prev, float)
        f -= 2.0 * self.P[0, :self.md.n].T @ self.dR @ up
        bps = self.md.res.breakpoints
        for i, s, k in self.binary_idx:  # eps (b - b_guess)^2: guess = segment of the reference
            guess = 1.0 if k < 0 else float(self.md.c @ ref[s] >= bps[k])
            f[i] -= 2.0 * EPS_REG * guess
        const = float(np.einsum("sx,xy,sy->", e[1:], self.Q, e[1:]) + up @ self.dR @ up)
        return f, const

    def for_modes(self, delta: Sequence[int | None]) -> HybridMiqp:
        """The problem whose blocks respect the mode schedule ``delta``: this one, or (built
        once, cached) the same horizon and weights with the blocks cut at the mode changes
        (:func:`split_blocks`)."""
        blocks = split_blocks(self.blocks, delta)
        if blocks == self.blocks:
            return self
        key = tuple(blocks)
        if key not in self._split:
            self._split[key] = HybridMiqp(self.md, self.N, *self._weights, blocks, self._dr)
        return self._split[key]

    def solve(self, x0: np.ndarray, ref: np.ndarray, lim: Limits,
              delta: Sequence[int | None], u_prev: np.ndarray | None = None) -> MiqpResult:
        """The MIQP for state ``x0``, references ``ref`` (N+1, 2n), limits, mode schedule and
        the last applied input ``u_prev`` (kN, for eq. 11); a block that spans a change of the
        fixed mode is cut there (:meth:`for_modes`)."""
        problem = self.for_modes(delta)
        if problem is not self:
            return problem.solve(x0, ref, lim, delta, u_prev)
        t0, c0 = time.perf_counter(), time.thread_time()
        f, const = self.linear_term(x0, ref, u_prev)
        lo, hi, sense, free = self.bounds(x0, lim, delta)
        res = self._solve(f, const, lo, hi, sense, x0, t0, free)
        if not res.feasible and 0 < free <= ENUMERATE_MAX_FREE:
            res = self._enumerate(f, const, lo, hi, sense, x0, t0, free)
            res.status += " (enumerated)"
        res.cpu_time = time.thread_time() - c0
        return res

    def _solve(self, f: np.ndarray, const: float, lo: np.ndarray, hi: np.ndarray,
               sense: np.ndarray, x0: np.ndarray, t0: float, free: int) -> MiqpResult:
        if np.any(lo > hi + 1e-9):
            return self._failed("empty constraint set", t0, free)
        hi = np.maximum(hi, lo)
        # a fresh workspace per solve: DAQP's branch and bound leaves state behind that can
        # change a later answer; fresh, the result depends on the data alone, which the FMU
        # state (save/restore) needs. A failed solve (cycling, or a feasible problem declared
        # infeasible on near-degenerate big-M rows) is retried with more tolerant pivoting /
        # cycle detection
        nodes, status = 0, ""
        for attempt, settings in enumerate(_RETRY_SETTINGS):
            solver = self._setup()
            if settings:
                current = solver.settings
                current.update(settings)
                solver.settings = current
            solver.update(f=f, bupper=hi, blower=lo, sense=sense)
            V, _, flag, info = solver.solve()
            nodes += int(info.get("nodes", 0))
            if flag == 1 and np.all(np.isfinite(V)):
                status = "solved" if attempt == 0 else f"solved (retry {attempt})"
                break
        else:
            return self._failed(f"exitflag {flag}", t0, free, nodes)
        V = np.asarray(V, float)
        cost = float(0.5 * V @ self.H @ V + f @ V + const)
        states = self.stage_states_free(x0) + self.Gam @ V
        return MiqpResult(self.P[0, :self.md.n] @ V, V, states, cost, True, status,
                          time.perf_counter() - t0, nodes=nodes, free_binaries=free,
                          stage_w=self.P @ V, blocks=tuple(self.blocks))

    def _failed(self, status: str, t0: float, free: int, nodes: int = 0) -> MiqpResult:
        n = self.md.n
        return MiqpResult(np.full(n, np.nan), np.full(self.nV, np.nan),
                          np.full((self.N + 1, 2 * n), np.nan), math.inf, False, status,
                          time.perf_counter() - t0, nodes=nodes, free_binaries=free,
                          stage_w=np.full((self.N, self.md.nw), np.nan),
                          blocks=tuple(self.blocks))

    def solve_enumerated(self, x0: np.ndarray, ref: np.ndarray, lim: Limits,
                         delta: Sequence[int | None], u_prev: np.ndarray | None = None
                         ) -> MiqpResult:
        """Reference solution: every assignment of the free binaries as a QP (tests, N small)."""
        problem = self.for_modes(delta)
        if problem is not self:
            return problem.solve_enumerated(x0, ref, lim, delta, u_prev)
        t0 = time.perf_counter()
        f, const = self.linear_term(x0, ref, u_prev)
        lo, hi, sense, free = self.bounds(x0, lim, delta)
        return self._enumerate(f, const, lo, hi, sense, x0, t0, free)

    def _enumerate(self, f: np.ndarray, const: float, lo: np.ndarray, hi: np.ndarray,
                   sense: np.ndarray, x0: np.ndarray, t0: float, free: int) -> MiqpResult:
        idx = np.array([i for i, _, _ in self.binary_idx if lo[i] < hi[i]], dtype=int)
        best = self._failed("infeasible", t0, free)
        for bits in itertools.product((0.0, 1.0), repeat=idx.size):
            lo2, hi2 = lo.copy(), hi.copy()
            lo2[idx] = hi2[idx] = bits
            res = self._solve(f, const, lo2, hi2, sense, x0, t0, 0)
            if res.feasible and res.cost < best.cost:
                best = res
        best.free_binaries = free
        return best
