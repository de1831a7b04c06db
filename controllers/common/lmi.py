"""Kothare-style robust MPC as an LMI problem (seed 003, eqs. 22-26), built once with cvxpy.

For a polytopic model ``x+ = A(k) x + B(k) u``, ``[A, B] in Co{[A_j, B_j]}`` (eqs. 16-17), the
min-max of the infinite-horizon cost ``sum x'Q1 x + u'R u`` (eqs. 18-19) is bounded by
``V(x) = x' P x`` with ``P = gamma Qv^-1`` when (eq. 22) ``V`` decreases by at least the stage
cost at every vertex. With the state feedback ``u = F x``, ``F = Y Qv^-1``, the controller solves
at each event ::

    min gamma  over  gamma, Qv = Qv' > 0, Y
    [1, x'; x, Qv] >= 0                                                     (eq. 23)
    [Qv, (A_j Qv + B_j Y)', Qv Q1^.5, Y' R^.5;
     A_j Qv + B_j Y, Qv, 0, 0;
     Q1^.5 Qv, 0, gamma I, 0;
     R^.5 Y, 0, 0, gamma I] >= 0                   for every vertex j       (eq. 24)
    [u_max^2 I, Y; Y', Qv] >= 0                                             (eq. 25)
    [Qv, (A_j Qv + B_j Y)' C'; C (A_j Qv + B_j Y), y_max^2 I] >= 0  (optional, eq. 26)

(Kothare, Balakrishnan and Morari 1996, Automatica 32(10), Theorem 2 and section 3.2). The
problem is parametrised (cvxpy ``Parameter`` for ``x`` and every vertex ``A_j``, ``B_j``) and
disciplined-parametrised (DPP), so it is canonicalised once and an event only refills the
parameters. With Clarabel, an event goes straight to the solver: the parameter vector times
cvxpy's reduced parameter-to-data tensor gives the conic data ``(A, b)`` of
``min q'z  s.t.  A z + s = b, s in K`` (the same data, in the same layout, cvxpy builds), and a
fixed linear map (from cvxpy's inverse reductions, found once) takes the solver's ``z`` to
``gamma``, ``Qv`` and ``Y``. That data and map are kept on disk
(:func:`cosim.fmu.disk_cache.cached_arrays`, keyed by the problem's sizes and weights, this
module's code and the cvxpy and Clarabel versions), so a process that finds them there calls
Clarabel without importing cvxpy; cvxpy is imported when the problem itself is needed: the
path through ``problem.solve``, the fallback solver, a status other than solved, or data not
yet on disk. The paper's disturbance column ``D_j`` of eq. 24 is not used: the seed 003
controller absorbs the disturbance with integral action instead (``controllers.robust``).
"""

from __future__ import annotations

import functools
import math
import time
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from importlib import metadata
from typing import Any

import clarabel  # cvxpy's SDP solver, used by default (missing = error at import)
import numpy as np
import scipy.sparse as sp

from cosim.fmu.disk_cache import cached_arrays, source_digest

LMI_SOLVERS = ("clarabel", "scs")
OPTIMAL = "optimal"  # cvxpy's status of a solved problem (cvxpy.OPTIMAL)
CLARABEL_SOLVED = "Solved"  # Clarabel's status that cvxpy maps to OPTIMAL
_SOLVED = (OPTIMAL,)


# version of the cached direct data: this module and the cvxpy and Clarabel releases (read at
# import: an FMU's extracted copy of this file may be gone by the time a problem is built)
_CODE_VERSION = ",".join([source_digest(__file__), *(f"{name}={metadata.version(name)}"
                                                     for name in ("cvxpy", "clarabel"))])


def _clarabel_cones(zero: int, nonneg: int, soc: Sequence[int], psd: Sequence[int]) -> list:
    """Clarabel's cones for cone dimensions in the order of cvxpy's Clarabel interface (zero,
    nonnegative, second-order, PSD triangle)."""
    return ([clarabel.ZeroConeT(zero)] if zero else []) + (
        [clarabel.NonnegativeConeT(nonneg)] if nonneg else []) + [
        clarabel.SecondOrderConeT(int(d)) for d in soc] + [
        clarabel.PSDTriangleConeT(int(d)) for d in psd]


@dataclass(frozen=True)
class _CvxProblem:
    """The cvxpy problem of eqs. 23-26 and its parameters and variables."""

    problem: Any  # cvxpy.Problem
    x: Any  # Parameter (n,)
    A: list  # Parameters (n, n), one per vertex
    B: list  # Parameters (n, m)
    gamma: Any  # Variable
    Qv: Any  # Variable (n, n), symmetric
    Y: Any  # Variable (m, n)


@dataclass(frozen=True)
class LmiSolution:
    """One event's solution: gain ``F`` (u = F x), ``gamma``, ``Qv``, ``Y``, solver data."""

    F: np.ndarray
    gamma: float
    Qv: np.ndarray
    Y: np.ndarray
    status: str
    solve_time: float  # wall time of the solve: data, solver call(s), solution (s)
    cpu_time: float = 0.0  # CPU time of this process during those calls (s; load-independent)
    fallback: bool = False  # solved by the fallback solver after the first did not solve it

    @property
    def ok(self) -> bool:
        return self.status in _SOLVED


def _sqrtm_psd(M: np.ndarray) -> np.ndarray:
    w, V = np.linalg.eigh(0.5 * (M + M.T))
    return (V * np.sqrt(np.clip(w, 0.0, None))) @ V.T


class KothareLmi:
    """The LMI problem of eqs. 23-26 for ``n_vertices`` vertices of size ``(n, m)``.

    ``Q1`` (n x n, >= 0) and ``R`` (m x m, > 0) are fixed; ``u_max`` (per input; ``None``: no
    input LMI), ``C`` and ``y_max`` (``None``: no output LMI) too. :meth:`solve` takes the state
    and the vertices of this event.
    """

    def __init__(self, n: int, m: int, n_vertices: int, Q1: np.ndarray, R: np.ndarray,
                 u_max: Sequence[float] | None = None, C: np.ndarray | None = None,
                 y_max: Sequence[float] | None = None, solver: str = "clarabel",
                 fallback: str | None = None, direct: bool = True) -> None:
        """``fallback``: a solver of :data:`LMI_SOLVERS` that re-solves an event ``solver``
        leaves unsolved (an interior-point method may stop short of its tolerance, status
        "optimal_inaccurate", on a problem a first-order method solves), ``None``: none.
        ``direct``: with ``solver = "clarabel"``, call Clarabel on the conic data
        (:meth:`_solve_direct`) rather than through ``problem.solve``; both pass Clarabel the
        same data and settings."""
        if solver not in LMI_SOLVERS:
            raise ValueError(f"solver = {solver!r} must be one of {LMI_SOLVERS}")
        if fallback is not None and (fallback not in LMI_SOLVERS or fallback == solver):
            raise ValueError(f"fallback = {fallback!r} must be None or one of {LMI_SOLVERS} "
                             f"other than solver = {solver!r}")
        self.fallback = fallback
        if n_vertices < 1:
            raise ValueError(f"n_vertices = {n_vertices} must be >= 1")
        self.n, self.m, self.L, self.solver = n, m, n_vertices, solver
        self.Q1, self.R = np.asarray(Q1, float), np.asarray(R, float)
        self.u_max = None if u_max is None else np.asarray(u_max, float).reshape(m)
        self.C = None if C is None else np.atleast_2d(np.asarray(C, float))
        self.y_max = None if self.C is None or y_max is None else np.asarray(
            y_max, float).reshape(self.C.shape[0])
        self.solves = 0
        self._x = np.zeros(n)
        self.direct = direct and solver == "clarabel"
        if self.direct:
            self._load_direct()

    @functools.cached_property
    def _cvx(self) -> _CvxProblem:
        """The problem in cvxpy, parametrised in ``x`` and the vertices (DPP), built on first
        use."""
        import cvxpy as cp

        n, m = self.n, self.m
        Q1h, Rh = _sqrtm_psd(self.Q1), _sqrtm_psd(self.R)
        x = cp.Parameter(n, name="x")
        As = [cp.Parameter((n, n), name=f"A{j}") for j in range(self.L)]
        Bs = [cp.Parameter((n, m), name=f"B{j}") for j in range(self.L)]
        g = cp.Variable(name="gamma")
        Qv = cp.Variable((n, n), symmetric=True, name="Qv")
        Y = cp.Variable((m, n), name="Y")
        xc = cp.reshape(x, (n, 1), order="F")
        cons = [cp.bmat([[np.ones((1, 1)), xc.T], [xc, Qv]]) >> 0]              # eq. 23
        Zn, Zm, In, Im = np.zeros((n, n)), np.zeros((n, m)), np.eye(n), np.eye(m)
        for A, B in zip(As, Bs, strict=True):
            AQBY = A @ Qv + B @ Y
            M = cp.bmat([[Qv, AQBY.T, Qv @ Q1h, Y.T @ Rh],
                         [AQBY, Qv, Zn, Zm],
                         [Q1h @ Qv, Zn, g * In, Zm],
                         [Rh @ Y, Zm.T, Zm.T, g * Im]])
            cons.append(0.5 * (M + M.T) >> 0)                                   # eq. 24
        if self.u_max is not None:
            X = cp.Variable((m, m), symmetric=True, name="X")
            cons += [cp.bmat([[X, Y], [Y.T, Qv]]) >> 0,                         # eq. 25
                     cp.diag(X) <= self.u_max ** 2]
        if self.C is not None and self.y_max is not None:
            for A, B in zip(As, Bs, strict=True):
                CA = self.C @ (A @ Qv + B @ Y)
                M = cp.bmat([[Qv, CA.T], [CA, np.diag(self.y_max ** 2)]])
                cons.append(0.5 * (M + M.T) >> 0)                               # eq. 26
        problem = cp.Problem(cp.Minimize(g), cons)
        if not problem.is_dpp():
            raise AssertionError("Kothare LMI problem is not DPP")
        return _CvxProblem(problem, x, As, Bs, g, Qv, Y)

    @property
    def problem(self) -> Any:
        """The cvxpy problem (``cvxpy.Problem``; imports cvxpy)."""
        return self._cvx.problem

    def _load_direct(self) -> None:
        """The direct path's data (:meth:`_build_direct`), from the disk cache when there."""
        none = "none"
        key = [self.n, self.m, self.L, self.Q1, self.R,
               none if self.u_max is None else self.u_max,
               none if self.C is None else self.C, none if self.y_max is None else self.y_max]
        (sizes, t_data, t_indices, t_indptr, a_indices, a_indptr, b_rows, ab_cols, q, soc,
         psd, unpack) = cached_arrays("kothare_lmi_direct", _CODE_VERSION, key,
                                      self._build_direct)
        (n_rows, nz, split, t_rows, t_cols, const_col, x_col, zero, nonneg) = (
            int(v) for v in sizes)
        self._tensor = sp.csr_array((t_data, t_indices, t_indptr), shape=(t_rows, t_cols))
        self._a_index = (a_indices, a_indptr, (n_rows, nz))
        self._b_rows, self._split, self._n_rows = b_rows, split, n_rows
        self._pvec = np.zeros(t_cols)
        self._pvec[const_col] = 1.0
        self._x_col = x_col
        self._ab_cols = [(int(a), int(b)) for a, b in ab_cols]
        self._q = q
        self._P = sp.csc_array((nz, nz))
        self._cones = _clarabel_cones(zero, nonneg, soc, psd)
        self._settings = clarabel.DefaultSettings()
        self._settings.verbose = False
        self._unpack = unpack

    def _build_direct(self) -> tuple[np.ndarray, ...]:
        """The conic data of the problem as an affine map of the parameters, and the linear
        map from the solver's variable to ``(gamma, Qv, Y)``, from cvxpy's Clarabel chain, as
        the arrays :meth:`_load_direct` reads.

        Data: ``values = T @ [p; 1]`` with ``T`` cvxpy's reduced tensor (``ReducedMat``) and
        ``p`` the parameters flattened column-major at cvxpy's columns; ``values`` fill the
        fixed CSC pattern of ``[-A | b]`` (so with ``keep_zeros = False``, as cvxpy does). The
        objective ``q`` (here ``gamma``'s column) does not depend on the parameters. The
        solution map is linear (the reductions only copy and symmetrise entries), so it is
        found by inverting the chain at ``z = 0`` and at each unit vector."""
        import cvxpy as cp
        from cvxpy.lin_ops.lin_op import CONSTANT_ID
        from cvxpy.reductions.solution import Solution
        from cvxpy.reductions.solvers.conic_solvers.clarabel_conif import CLARABEL

        cvx = self._cvx
        cvx.x.value = np.zeros(self.n)
        for pa, pb in zip(cvx.A, cvx.B, strict=True):
            pa.value, pb.value = np.zeros((self.n, self.n)), np.zeros((self.n, self.m))
        data, chain, inverse = cvx.problem.get_problem_data(cp.CLARABEL)
        prog = data[cp.settings.PARAM_PROB]
        prog.reduced_A.cache(False)
        tensor = sp.csr_array(prog.reduced_A.reduced_mat)
        indices, indptr, shape = prog.reduced_A.problem_data_index
        nz = prog.x.size
        split = int(indptr[nz])
        cols = prog.param_id_to_col
        dims = data[CLARABEL.DIMS]
        if dims.exp or len(dims.p3d) or len(getattr(dims, "pnd", ())):
            raise AssertionError("Kothare LMI problem has cones beyond zero, nonneg, SOC, PSD")
        var_id = inverse[-1][CLARABEL.VAR_ID]

        def recover(z: np.ndarray) -> np.ndarray:
            sol = Solution(cp.OPTIMAL, 0.0, {var_id: z}, {}, {})
            for reduction, data in reversed(list(zip(chain.reductions[:-1], inverse[:-1],
                                                     strict=True))):
                sol = reduction.invert(sol, data)
            vals = sol.primal_vars
            return np.concatenate([np.asarray(vals[v.id], float).ravel(order="F")
                                   for v in (cvx.gamma, cvx.Qv, cvx.Y)])

        offset = recover(np.zeros(nz))
        if np.any(offset != 0.0):
            raise AssertionError("solution map of the Kothare LMI problem is not linear")
        unpack = np.column_stack([recover(np.eye(nz)[i]) for i in range(nz)])
        if tensor.shape[1] != prog.total_param_size + 1:
            raise AssertionError("parameter tensor of the Kothare LMI problem: unexpected width")
        sizes = np.array([shape[0], nz, split, tensor.shape[0], tensor.shape[1],
                          cols[CONSTANT_ID], cols[cvx.x.id], dims.zero, dims.nonneg])
        ab_cols = np.array([(cols[pa.id], cols[pb.id]) for pa, pb in zip(cvx.A, cvx.B,
                                                                         strict=True)])
        return (sizes, tensor.data, tensor.indices, tensor.indptr,
                np.asarray(indices[:split]), np.asarray(indptr[:nz + 1]),
                np.asarray(indices[split:]), ab_cols,
                np.asarray(data[cp.settings.C], float).copy(),
                np.array(dims.soc, dtype=np.int64), np.array(dims.psd, dtype=np.int64), unpack)

    def solver_options(self, solver: str | None = None) -> dict:
        """The solver (default: ``solver``) and its tolerances: Clarabel's defaults (gap and
        feasibility 1e-8); SCS (first order) at 1e-4, its default accuracy (at 1e-6 it does
        not converge in 20000 iterations on these problems; at 1e-4 it takes thousands, ~40x
        Clarabel's time)."""
        if (solver or self.solver) == "clarabel":
            return {"solver": "CLARABEL"}
        return {"solver": "SCS", "eps_abs": 1e-4, "eps_rel": 1e-4, "max_iters": 100000}

    @property
    def tolerance(self) -> float:
        """Relative accuracy the solver is asked for (gap / feasibility)."""
        return 1e-8 if self.solver == "clarabel" else 1e-4

    def _solve_with(self, solver: str) -> str:
        from cvxpy.error import SolverError

        try:
            self.problem.solve(**self.solver_options(solver))
            return str(self.problem.status)
        except SolverError as exc:
            return f"solver error: {exc}"

    def _solve_direct(self, x: np.ndarray, vertices: Sequence[tuple[np.ndarray, np.ndarray]]
                      ) -> tuple[str, np.ndarray | None]:
        """Clarabel on the conic data at ``(x, vertices)``: cvxpy's status (a solver error
        gives the message of cvxpy's ``SolverError``) and ``[gamma, vec Qv, vec Y]``
        (column-major) when a solution is present, else ``None``."""
        n, m, pv = self.n, self.m, self._pvec
        pv[self._x_col:self._x_col + n] = x
        for (A, B), (ca, cb) in zip(vertices, self._ab_cols, strict=True):
            pv[ca:ca + n * n] = np.asarray(A, float).ravel(order="F")
            pv[cb:cb + n * m] = np.asarray(B, float).ravel(order="F")
        values = self._tensor @ pv
        k = self._split
        A_data = sp.csc_array((-values[:k], self._a_index[0], self._a_index[1]),
                              shape=self._a_index[2])
        b = np.zeros(self._n_rows)
        np.add.at(b, self._b_rows, values[k:])
        result = clarabel.DefaultSolver(self._P, self._q, A_data, b, self._cones,
                                        self._settings).solve()
        if str(result.status) == CLARABEL_SOLVED:
            return OPTIMAL, self._unpack @ np.asarray(result.x, float)
        import cvxpy as cp
        from cvxpy.reductions.solvers.conic_solvers.clarabel_conif import CLARABEL

        status = CLARABEL.STATUS_MAP.get(str(result.status), cp.settings.SOLVER_ERROR)
        if status in cp.settings.INACCURATE:
            warnings.warn("Solution may be inaccurate. Try another solver, adjusting the "
                          "solver settings, or solve with verbose=True for more "
                          "information.", stacklevel=3)
        if status in cp.settings.ERROR:
            return ("solver error: Solver 'CLARABEL' failed. Try another solver, or solve "
                    "with verbose=True for more information.", None)
        if status not in cp.settings.SOLUTION_PRESENT:
            return status, None
        return status, self._unpack @ np.asarray(result.x, float)

    def _set_parameters(self, vertices: Sequence[tuple[np.ndarray, np.ndarray]]) -> None:
        cvx = self._cvx
        cvx.x.value = self._x
        for (A, B), pa, pb in zip(vertices, cvx.A, cvx.B, strict=True):
            pa.value = np.asarray(A, float).reshape(self.n, self.n)
            pb.value = np.asarray(B, float).reshape(self.n, self.m)

    def _cvx_solution(self) -> np.ndarray | None:
        """``[gamma, vec Qv, vec Y]`` (column-major) of the cvxpy problem's last solve."""
        cvx = self._cvx
        if cvx.Qv.value is None:
            return None
        return np.concatenate([np.ravel(cvx.gamma.value), np.ravel(cvx.Qv.value, order="F"),
                               np.ravel(cvx.Y.value, order="F")])

    def solve(self, x: np.ndarray, vertices: Sequence[tuple[np.ndarray, np.ndarray]]
              ) -> LmiSolution:
        """Solve at state ``x`` for the vertices ``[(A_j, B_j)]`` (exactly ``n_vertices``)."""
        if len(vertices) != self.L:
            raise ValueError(f"{len(vertices)} vertices given, problem built for {self.L}")
        n, m = self.n, self.m
        self._x = np.asarray(x, float).reshape(n).copy()
        t0, c0 = time.perf_counter(), time.process_time()
        if self.direct:
            status, z = self._solve_direct(self._x, vertices)
        else:
            self._set_parameters(vertices)
            status = self._solve_with(self.solver)
            z = self._cvx_solution()
        fallback = False
        if (status not in _SOLVED or z is None) and self.fallback is not None:
            if self.direct:
                self._set_parameters(vertices)
            status, fallback = self._solve_with(self.fallback), True
            z = self._cvx_solution()
        dt, cpu = time.perf_counter() - t0, time.process_time() - c0
        self.solves += 1
        if status not in _SOLVED or z is None:
            nan = np.full((m, n), math.nan)
            return LmiSolution(nan, math.nan, np.full((n, n), math.nan), nan,
                               status, dt, cpu, fallback)
        Qv = z[1:1 + n * n].reshape(n, n, order="F")
        Y = z[1 + n * n:].reshape(m, n, order="F")
        F = np.linalg.solve(Qv.T, Y.T).T  # Y Qv^-1
        return LmiSolution(F, float(z[0]), Qv, Y, status, dt, cpu, fallback)

    def vertex_matrices(self, sol: LmiSolution,
                        vertices: Sequence[tuple[np.ndarray, np.ndarray]]
                        ) -> list[np.ndarray]:
        """The numeric left-hand sides of eqs. 23-25 at a solution (for checks)."""
        n, m = self.n, self.m
        Q1h, Rh = _sqrtm_psd(self.Q1), _sqrtm_psd(self.R)
        Qv, Y, g = sol.Qv, sol.Y, sol.gamma
        x = self._x.reshape(n, 1)
        out = [np.block([[np.ones((1, 1)), x.T], [x, Qv]])]
        for A, B in vertices:
            AQBY = A @ Qv + B @ Y
            out.append(np.block([[Qv, AQBY.T, Qv @ Q1h, Y.T @ Rh],
                                 [AQBY, Qv, np.zeros((n, n)), np.zeros((n, m))],
                                 [Q1h @ Qv, np.zeros((n, n)), g * np.eye(n), np.zeros((n, m))],
                                 [Rh @ Y, np.zeros((m, n)), np.zeros((m, n)), g * np.eye(m)]]))
        return out
