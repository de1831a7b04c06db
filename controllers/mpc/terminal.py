"""Maximal robust positively invariant (RPI) set of ``e+ = A e + w``, ``w in W``, in a polytope.

Terminal set of the tube controllers (eq. 16-18): the largest set ``O`` with ``C e <= h`` on
``O`` and ``A O (+) W subset O``. The standard recursion (Kolmanovsky and Gilbert 1998)::

    O = { e : C A^k e <= h - sum_{j<k} h_W((C A^j)') ,  k = 0, 1, ... }

stops at the first ``k`` whose rows are all redundant for the rows already kept (an LP per
row while the set is unbounded, HiGHS; then the maximum over its vertices, qhull); then ``O``
is exactly the maximal RPI set. Each new row is kept only when it cuts the set, so the
polytope stays small. Results are cached per data, in the process (the sweep workers build the
same controller many times) and on disk (:mod:`cosim.fmu.disk_cache`: a further process needs
neither the LPs nor scipy's ~0.3 s of imports).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from cosim.fmu.disk_cache import cached_arrays, source_digest

_VERSION = source_digest(__file__)


def _cut(rows: np.ndarray, rhs: np.ndarray, f: np.ndarray, bound: float) -> bool | None:
    """Does ``f e <= bound`` cut ``{rows e <= rhs}``? None if that set is empty."""
    from scipy.optimize import linprog

    res = linprog(-f, A_ub=rows, b_ub=rhs, bounds=[(None, None)] * len(f), method="highs")
    if res.status == 2:
        return None
    if res.status == 3:  # unbounded along f: the row cuts
        return True
    if res.status != 0:
        raise RuntimeError(f"terminal set: LP failed ({res.message})")
    slack = 1e-9 * max(1.0, abs(bound))
    return -res.fun > bound + slack


def _vertices(rows: np.ndarray, rhs: np.ndarray, bounded: bool) -> np.ndarray | None:
    """Vertices of ``{rows e <= rhs}`` (qhull) when it is bounded (known, or checked by LPs)
    with an interior; None while unbounded. Raises ValueError when it is empty."""
    from scipy.optimize import linprog
    from scipy.spatial import HalfspaceIntersection

    n = rows.shape[1]
    norms = np.linalg.norm(rows, axis=1)
    if bounded and np.all(rhs > 1e-9 * norms * max(1.0, np.abs(rhs).max())):
        # the origin is interior (W holds 0, so the set does): no LP for a centre
        return HalfspaceIntersection(np.c_[rows, -rhs], np.zeros(n)).intersections
    # Chebyshev centre: max r with rows e + |row| r <= rhs (an interior point for qhull)
    res = linprog(np.r_[np.zeros(n), -1.0], A_ub=np.c_[rows, norms], b_ub=rhs,
                  bounds=[(None, None)] * n + [(0.0, None)], method="highs")
    if res.status == 2:
        raise ValueError("terminal set: empty (W too large for the constraints)")
    if res.status == 3:
        return None  # unbounded radius: the set is unbounded
    if res.status != 0:
        raise RuntimeError(f"terminal set: LP failed ({res.message})")
    center, radius = res.x[:n], res.x[n]
    if radius <= 1e-12 * max(1.0, np.abs(rhs).max()):
        raise ValueError("terminal set: empty interior (W too large for the constraints)")
    if not bounded and _bounding_box(rows, rhs) is None:
        return None
    hs = HalfspaceIntersection(np.c_[rows, -rhs], center)
    return hs.intersections


def _bounding_box(rows: np.ndarray, rhs: np.ndarray) -> np.ndarray | None:
    """``[lo, hi]`` of ``{rows e <= rhs}`` per coordinate, None while unbounded."""
    from scipy.optimize import linprog

    n = rows.shape[1]
    box = np.zeros((2, n))
    for i in range(n):
        for j, sign in enumerate((-1.0, 1.0)):
            res = linprog(-sign * np.eye(n)[i], A_ub=rows, b_ub=rhs, bounds=[(None, None)] * n,
                          method="highs")
            if res.status != 0:
                return None
            box[j, i] = -sign * res.fun
    return box


def robust_invariant_set(A: np.ndarray, C: np.ndarray, h: np.ndarray, w_vertices: np.ndarray,
                         max_steps: int = 500) -> tuple[np.ndarray, np.ndarray]:
    """``(rows, rhs)`` of the maximal RPI set of ``e+ = A e + w`` (``w`` in the convex hull of
    ``w_vertices``) inside ``C e <= h``. Raises ValueError when it is empty or not finitely
    determined within ``max_steps``."""
    key = (A.tobytes(), A.shape, C.tobytes(), C.shape, np.asarray(h, float).tobytes(),
           np.asarray(w_vertices, float).tobytes(), np.shape(w_vertices), max_steps)
    rows, rhs = _cached(key)
    return rows.copy(), rhs.copy()


@lru_cache(maxsize=64)
def _cached(key: tuple) -> tuple[np.ndarray, np.ndarray]:
    a_b, a_shape, c_b, c_shape, h_b, w_b, w_shape, max_steps = key
    A = np.frombuffer(a_b).reshape(a_shape)
    C = np.frombuffer(c_b).reshape(c_shape)
    h = np.frombuffer(h_b).copy()
    W = np.frombuffer(w_b).reshape(w_shape)
    rows, rhs = cached_arrays("mrpi", _VERSION, [A, C, h, W, max_steps],
                              lambda: _maximal_rpi(A, C, h, W, max_steps))
    return rows, rhs


def _maximal_rpi(A: np.ndarray, C: np.ndarray, h: np.ndarray, W: np.ndarray,
                 max_steps: int) -> tuple[np.ndarray, np.ndarray]:
    """The recursion of the module docstring (uncached)."""
    if np.any(np.max(C @ W.T, axis=1) > h):
        raise ValueError("terminal set: the disturbance set W alone leaves the constraints")
    rows, rhs = C.copy(), h.copy()
    Ck, margin = C.copy(), np.zeros(len(h))
    verts = None  # vertices of the current set once it is bounded: exact redundancy test
    for _ in range(max_steps):
        margin = margin + np.max(Ck @ W.T, axis=1)  # sum_{j<=k} h_W(C A^j)
        Ck = Ck @ A
        bound = h - margin
        new = []
        for f, b in zip(Ck, bound, strict=True):
            tol = 1e-9 * max(1.0, abs(b))
            if verts is not None:
                if np.max(verts @ f) > b + tol:
                    new.append((f, b))
                continue
            cut = _cut(rows, rhs, f, b)
            if cut is None:
                raise ValueError("terminal set: empty (W too large for the constraints)")
            if cut:
                new.append((f, b))
        if not new:
            return rows, rhs
        rows = np.vstack([rows] + [f[None, :] for f, _ in new])
        rhs = np.concatenate([rhs, [b for _, b in new]])
        verts = _vertices(rows, rhs, verts is not None)  # bounded stays bounded
    raise ValueError(f"terminal set: not finitely determined within {max_steps} steps")
