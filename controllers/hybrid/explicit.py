"""Explicit hybrid MPC (EMPC) of seed 004 (section 2.3, eq. 18): region data and point location.

The online MIQP of eq. 15 (:mod:`controllers.hybrid.miqp`) has two kinds of binaries: the mode
``delta`` (fixed by the schedule of section 3) and the PWA segment of each stage. EMPC splits it
into one multiparametric QP per mode and segment (6 mp-QPs), each with the mode and segment held
over the horizon (the segment of the measured mean speed): the piecewise-affine law of eq. 18,
``u = F_i theta + f_i`` on polyhedral regions ``E_i theta <= e_i``, is then the union of their
solutions. Parameters ``theta`` (:data:`PARAM_NAMES`):

* ``e``: mean speed minus reference speed (m/s); ``dv12, dv23``: speed differences of adjacent
  cars (mm/s, so that every parameter's range is O(1)..O(100)); ``f12, f23``: coupler forces
  (kN). With the mean speed they give the state
  ``x = [v, x]`` of :class:`controllers.hybrid.model.ChainModel` (displacements relative to
  the head, as the GMPC rebuilds them);
* ``v_ref``: reference speed now (m/s); ``a_ref``: reference slope over the horizon (m/s^2).
  The reference of stage ``s`` is ``v_ref + a_ref s Ts`` and, for the displacements, its
  integral from now (the GMPC's default ``position_reference = "horizon"``);
* ``limit``: traction limit of a motor car (traction) or brake limit of car 1 (braking), kN; the
  other cars' limits are fixed multiples (equal motors; brake force proportional to mass).

Decision ``U``: the forces (kN) of the cars that act in the mode (motor cars in traction, every
car in braking, so trailers never brake while the train pulls), per block of stages. Cost as the
GMPC's: ``sum_s ||x_s - r_s||_Q^2 + ||u_s||_R^2``; constraints: the envelope bounds. The coupler
force and speed rows of the GMPC are left out: on the seed 004 runs they never bind (the GMPC's
presolve drops them as unreachable), and each would multiply the regions.

The region data (``F, f`` of the first move only, ``E, e``, a bounding box per region) is made
offline by ``papers/seed004/make_empc_regions.py`` (PPOPT, optional extra ``empc-offline``) and
stored as a compressed ``.npz`` next to this module; online only numpy is needed. Point
location: a binary search tree over the regions' bounding boxes (:class:`BoxTree`, built at
load): each node splits one parameter at a threshold, regions whose box straddles it go to both
sides; a query descends one path and tests the few regions of its leaf.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from controllers.hybrid.locate import compiled_locator
from controllers.hybrid.model import ChainModel

PARAM_NAMES = ("e", "dv12", "dv23", "f12", "f23", "v_ref", "a_ref", "limit")
MODES = (0, 1)  # delta: 0 braking, 1 traction
DATA_DIR = Path(__file__).resolve().parent / "data"


@dataclass(frozen=True)
class ParametricQp:
    """One mp-QP (PPOPT's form)::

        min_U 1/2 U'Qp U + theta'Hp'U + cp'U   s.t.  G U <= w + S theta,  At theta <= bt

    plus :meth:`state` / :meth:`reference` maps used to check it against the condensed MPC.
    """

    Qp: np.ndarray
    Hp: np.ndarray  # (nU, ntheta)
    cp: np.ndarray
    G: np.ndarray
    w: np.ndarray
    S: np.ndarray
    At: np.ndarray
    bt: np.ndarray
    active: np.ndarray  # indices of the cars that act in this mode
    n_first: int  # inputs of the first block = len(active)

    def first_input(self, U: np.ndarray, n: int) -> np.ndarray:
        """The n-car force vector (kN) of the first stage."""
        u = np.zeros(n)
        u[self.active] = U[:self.n_first]
        return u


def theta_maps(model: ChainModel) -> tuple[np.ndarray, np.ndarray]:
    """``(Tx, tx)`` with state ``x0 = Tx theta + tx`` (displacements relative to the head)."""
    n, c = model.n, model.m / model.m.sum()
    if n != 3:
        raise ValueError(f"EMPC parameters are written for 3 cars, the model has {n}")
    T = np.zeros((2 * n, len(PARAM_NAMES)))
    one = np.eye(len(PARAM_NAMES))
    mm = 1e-3  # dv in mm/s
    # speeds: v1 = vm + (c2 + c3) dv12 + c3 dv23, v2 = v1 - dv12, v3 = v2 - dv23; vm = e + v_ref
    T[0] = one[0] + one[5] + mm * ((c[1] + c[2]) * one[1] + c[2] * one[2])
    T[1] = T[0] - mm * one[1]
    T[2] = T[1] - mm * one[2]
    # displacements: x1 = 0, x_j+1 = x_j - (F_j - d dv_j) / k (F in kN)
    k, d = model.k, model.d
    T[4] = -(1e3 * one[3] - d * mm * one[1]) / k
    T[5] = T[4] - (1e3 * one[4] - d * mm * one[2]) / k
    return T, np.zeros(2 * n)


def reference_maps(model: ChainModel, horizon: int) -> np.ndarray:
    """``R[s]`` with reference ``r_s = R[s] theta`` (s = 0..N)."""
    n, Ts = model.n, model.Ts
    iv, ia = PARAM_NAMES.index("v_ref"), PARAM_NAMES.index("a_ref")
    R = np.zeros((horizon + 1, 2 * n, len(PARAM_NAMES)))
    for s in range(horizon + 1):
        R[s, :n, iv], R[s, :n, ia] = 1.0, s * Ts
        R[s, n:, iv], R[s, n:, ia] = s * Ts, 0.5 * (s * Ts) ** 2
    return R


def parametric_qp(model: ChainModel, horizon: int, blocks: Sequence[int], q: Sequence[float],
                  r: float, mode: int, segment: int, box: np.ndarray,
                  limit_ratio: np.ndarray) -> ParametricQp:
    """The mp-QP of mode ``mode`` and PWA segment ``segment`` (held over the horizon);
    ``box`` (ntheta, 2) bounds the parameters; ``limit_ratio[i]`` scales ``limit`` to car i."""
    n, N = model.n, int(horizon)
    blocks = [int(b) for b in blocks]
    if sum(blocks) != N:
        raise ValueError(f"blocks {blocks} must sum to N = {N}")
    active = np.flatnonzero(model.motored) if mode == 1 else np.arange(n)
    na, nb = active.size, len(blocks)
    nU, nth = na * nb, len(PARAM_NAMES)
    stage_block = np.repeat(np.arange(nb), blocks)
    A = model.A_seg(segment)
    f_aff = model.res.alpha[segment] * model.g
    Tx, tx = theta_maps(model)
    Rf = reference_maps(model, N)
    Q = np.diag(np.asarray(q, float))
    Qp = np.zeros((nU, nU))
    Hp = np.zeros((nU, nth))
    cp = np.zeros(nU)
    Phi, Gam, fs = np.eye(2 * n), np.zeros((2 * n, nU)), np.zeros(2 * n)
    for s in range(N):
        Ps = np.zeros((n, nU))  # u_s = Ps U
        j = stage_block[s]
        Ps[active, na * j + np.arange(na)] = 1.0
        Qp += 2.0 * r * Ps.T @ Ps
        Phi, Gam, fs = A @ Phi, A @ Gam + model.B @ Ps, A @ fs + f_aff
        M = Phi @ Tx - Rf[s + 1]  # error e_s = M theta + Gam U + c
        c = Phi @ tx + fs
        Qp += 2.0 * Gam.T @ Q @ Gam
        Hp += 2.0 * Gam.T @ Q @ M
        cp += 2.0 * Gam.T @ Q @ c
    il = PARAM_NAMES.index("limit")
    ratio = np.asarray(limit_ratio, float)[active]
    G = np.vstack([np.eye(nU), -np.eye(nU)])
    w = np.zeros(2 * nU)
    S = np.zeros((2 * nU, nth))
    rows = (np.arange(nU) if mode == 1 else nU + np.arange(nU))  # u <= T or -u <= B
    S[rows, il] = np.tile(ratio, nb)
    box = np.asarray(box, float)
    At = np.vstack([np.eye(nth), -np.eye(nth)])
    bt = np.concatenate([box[:, 1], -box[:, 0]])
    return ParametricQp(0.5 * (Qp + Qp.T), Hp, cp, G, w, S, At, bt, active, na)


def solve_parametric(qp: ParametricQp, theta: np.ndarray) -> np.ndarray:
    """The QP at one ``theta`` (DAQP; the online problem the regions were built from)."""
    import daqp

    lin = qp.Hp @ theta + qp.cp
    upper = qp.w + qp.S @ theta
    lower = np.full(upper.size, -1e30)
    x, _, flag, _ = daqp.solve(qp.Qp, lin, qp.G, upper, lower, np.zeros(upper.size, np.int32))
    if flag != 1:
        raise ValueError(f"DAQP exitflag {flag} at theta = {theta}")
    return np.asarray(x)


class BoxTree:
    """Binary search tree over axis-aligned boxes ``lo[i] <= theta <= hi[i]``.

    Node ``k``: split dimension ``dim[k]`` (``-1``: leaf) and threshold ``thr[k]``; children
    ``left[k]`` (theta[dim] <= thr) and ``right[k]``; a leaf lists ``items[start[k]:stop[k]]``.
    A box straddling a threshold is listed on both sides; splitting stops at ``leaf_size``
    items or when a split would not shrink both sides.
    """

    def __init__(self, lo: np.ndarray, hi: np.ndarray, leaf_size: int = 8,
                 max_depth: int = 40) -> None:
        self.lo, self.hi = np.asarray(lo, float), np.asarray(hi, float)
        dim: list[int] = []
        thr: list[float] = []
        left: list[int] = []
        right: list[int] = []
        start: list[int] = []
        stop: list[int] = []
        items: list[int] = []
        stack = [(np.arange(self.lo.shape[0]), 0, -1, False)]
        while stack:
            idx, depth, parent, is_right = stack.pop()
            k = len(dim)
            if parent >= 0:
                (right if is_right else left)[parent] = k
            dim.append(-1)
            thr.append(0.0)
            left.append(-1)
            right.append(-1)
            start.append(len(items))
            stop.append(len(items))
            split = None
            if idx.size > leaf_size and depth < max_depth:
                centre = 0.5 * (self.lo[idx] + self.hi[idx])
                best = None
                for dd in np.argsort(-np.ptp(centre, axis=0))[:4]:
                    t = float(np.median(centre[:, dd]))
                    nl = int(np.count_nonzero(self.lo[idx, dd] <= t))
                    nr = int(np.count_nonzero(self.hi[idx, dd] >= t))
                    if nl < idx.size and nr < idx.size:
                        worst = max(nl, nr)
                        if best is None or worst < best[0]:
                            best = (worst, int(dd), t)
                if best is not None:
                    split = best[1:]
            if split is None:
                items.extend(int(i) for i in idx)
                stop[k] = len(items)
                continue
            dd, t = split
            dim[k], thr[k] = dd, t
            stack.append((idx[self.hi[idx, dd] >= t], depth + 1, k, True))
            stack.append((idx[self.lo[idx, dd] <= t], depth + 1, k, False))
        self.dim = np.array(dim, np.int64)
        self.thr = np.array(thr)
        self.left = np.array(left, np.int64)
        self.right = np.array(right, np.int64)
        self.start = np.array(start, np.int64)
        self.stop = np.array(stop, np.int64)
        self.items = np.array(items, np.int64)
        depth_max, todo = 0, [(0, 0)]
        while todo:
            k, dep = todo.pop()
            depth_max = max(depth_max, dep)
            if self.dim[k] >= 0:
                todo += [(int(self.left[k]), dep + 1), (int(self.right[k]), dep + 1)]
        self.depth = depth_max

    def candidates(self, theta: np.ndarray) -> np.ndarray:
        """Items whose boxes may hold ``theta`` (those of the leaf ``theta`` falls in)."""
        k = 0
        dim, thr = self.dim, self.thr
        while dim[k] >= 0:
            k = self.left[k] if theta[dim[k]] <= thr[k] else self.right[k]
        return self.items[self.start[k]:self.stop[k]]


class RegionSet:
    """The regions of one mp-QP: ``E[i] theta <= e[i]`` -> ``u = F[i] theta + f[i]`` (first
    move, active cars only), stored flat (row offsets ``rows``)."""

    def __init__(self, E: np.ndarray, e: np.ndarray, rows: np.ndarray, F: np.ndarray,
                 f: np.ndarray, box_lo: np.ndarray, box_hi: np.ndarray, tol: float = 1e-7,
                 leaf_size: int = 8, compiled: bool = True) -> None:
        self.E = np.ascontiguousarray(E, dtype=float)
        self.e = np.ascontiguousarray(e, dtype=float)
        self.rows = np.ascontiguousarray(rows, dtype=np.int64)
        self.F, self.f = F, f
        self.count = F.shape[0]
        self.tol = float(tol)
        self.tree = BoxTree(box_lo, box_hi, leaf_size=leaf_size)
        # the compiled lookup (controllers.hybrid.locate) where numba is installed
        self._kernel = compiled_locator() if compiled else None

    def violation(self, i: int, theta: np.ndarray) -> float:
        a, b = self.rows[i], self.rows[i + 1]
        return float(np.max(self.E[a:b] @ theta - self.e[a:b]))

    @property
    def compiled(self) -> bool:
        """Does :meth:`locate` run the compiled kernel (else the numpy reference)?"""
        return self._kernel is not None

    def locate(self, theta: np.ndarray) -> tuple[int, float]:
        """``(region, violation)``: the first leaf candidate holding ``theta`` (violation <=
        tol), else the candidate violated least (theta on a gap between regions, e.g. an
        omitted tiny region; -1 if the leaf is empty). Compiled where numba is installed,
        else :meth:`locate_reference`."""
        if self._kernel is None:
            return self.locate_reference(theta)
        t = self.tree
        i, v = self._kernel(self.E, self.e, self.rows, t.dim, t.thr, t.left, t.right,
                            t.start, t.stop, t.items, self.tol,
                            np.ascontiguousarray(theta, dtype=float))
        return int(i), float(v)

    def locate_reference(self, theta: np.ndarray) -> tuple[int, float]:
        """:meth:`locate` in numpy (the reference of the compiled kernel)."""
        best, best_v = -1, math.inf
        for i in self.tree.candidates(theta):
            v = self.violation(int(i), theta)
            if v <= self.tol:
                return int(i), v
            if v < best_v:
                best, best_v = int(i), v
        return best, best_v

    def scan(self, theta: np.ndarray) -> list[int]:
        """Every region holding ``theta`` (brute force, for tests)."""
        return [i for i in range(self.count) if self.violation(i, theta) <= self.tol]

    def control(self, i: int, theta: np.ndarray) -> np.ndarray:
        return self.F[i] @ theta + self.f[i]


@dataclass
class ExplicitLaw:
    """All mp-QPs of one controller design, keyed by (mode, segment), with the design's
    settings (``meta``) to check a controller against."""

    sets: dict[tuple[int, int], RegionSet]
    boxes: dict[tuple[int, int], np.ndarray]
    meta: dict[str, float | str]

    @classmethod
    def load(cls, path: Path) -> ExplicitLaw:
        with np.load(path, allow_pickle=False) as z:
            data = {k: z[k] for k in z.files}
        meta = {str(k): str(v) for k, v in zip(data["meta_keys"], data["meta_values"],
                                                strict=True)}  # as written; compared by type
        sets, boxes = {}, {}
        for key in data["keys"]:
            mode, seg = (int(x) for x in key)
            p = f"m{mode}s{seg}_"
            sets[mode, seg] = RegionSet(data[p + "E"], data[p + "e"], data[p + "rows"],
                                        data[p + "F"], data[p + "f"], data[p + "lo"],
                                        data[p + "hi"])
            boxes[mode, seg] = data[p + "box"]
        return cls(sets, boxes, meta)

    def save(self, path: Path) -> None:
        arrays: dict[str, np.ndarray] = {
            "keys": np.array(sorted(self.sets), np.int64),
            "meta_keys": np.array(list(self.meta)),
            "meta_values": np.array([str(v) for v in self.meta.values()]),
        }
        for (mode, seg), rs in self.sets.items():
            p = f"m{mode}s{seg}_"
            arrays.update({p + "E": rs.E, p + "e": rs.e, p + "rows": rs.rows, p + "F": rs.F,
                           p + "f": rs.f, p + "lo": rs.tree.lo, p + "hi": rs.tree.hi,
                           p + "box": self.boxes[mode, seg]})
        np.savez_compressed(path, **arrays)

