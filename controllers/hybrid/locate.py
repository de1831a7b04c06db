"""Compiled point location of the explicit MPC (seed 004, eq. 18): the descent of
:class:`controllers.hybrid.explicit.BoxTree` and the region test of
:meth:`controllers.hybrid.explicit.RegionSet.locate` in one numba kernel.

:func:`locate` is the same algorithm as the numpy reference (``RegionSet.locate_reference``):
descend the tree (``theta[dim] <= thr``: left), test the leaf's regions in order, return the
first whose largest row violation ``max_r (E_r theta - e_r)`` is at most ``tol``, else the
least violated (-1 for an empty leaf). The row products are summed in index order (numpy's
BLAS may use another order or fused multiply-adds), so a region can differ from the
reference's only for a ``theta`` within rounding of a region's face (``tests/test_explicit_mpc
.py`` checks both choices hold ``theta`` to that rounding).

numba is a dependency of the project (the plant kernels, :mod:`plants.kernels`); it is imported
and the kernel compiled (eagerly, for float64/int64 arrays) by :func:`compiled_locator`, once
per process, so the import of this module costs nothing. Without numba (or with
``ATO_COSIM_NO_KERNELS`` set) :func:`compiled_locator` returns None and the explicit MPC runs
the numpy reference.
"""

from __future__ import annotations

import importlib.util
import math
import os
import threading
from collections.abc import Callable

import numpy as np

KERNELS = (importlib.util.find_spec("numba") is not None
           and os.environ.get("ATO_COSIM_NO_KERNELS", "") == "")
_SIGNATURE = ("Tuple((int64, float64))(float64[:, ::1], float64[::1], int64[::1], int64[::1], "
              "float64[::1], int64[::1], int64[::1], int64[::1], int64[::1], int64[::1], "
              "float64, float64[::1])")
_LOCK = threading.Lock()
_compiled: list[Callable | None] = []


def locate(E: np.ndarray, e: np.ndarray, rows: np.ndarray, dim: np.ndarray, thr: np.ndarray,
           left: np.ndarray, right: np.ndarray, start: np.ndarray, stop: np.ndarray,
           items: np.ndarray, tol: float, theta: np.ndarray) -> tuple[int, float]:
    """``(region, violation)`` of ``theta`` (module docstring); plain Python until compiled."""
    k = 0
    while dim[k] >= 0:
        k = left[k] if theta[dim[k]] <= thr[k] else right[k]
    best, best_v = -1, math.inf
    for q in range(start[k], stop[k]):
        i = items[q]
        worst = -math.inf
        for r in range(rows[i], rows[i + 1]):
            dot = 0.0
            for j in range(theta.size):
                dot += E[r, j] * theta[j]
            x = dot - e[r]
            if r == rows[i] or x > worst:
                worst = x
        if worst <= tol:
            return i, worst
        if worst < best_v:
            best, best_v = i, worst
    return best, best_v


def compiled_locator() -> Callable | None:
    """:func:`locate` compiled by numba (once per process), or None without numba."""
    if not KERNELS:
        return None
    with _LOCK:
        if not _compiled:
            try:
                import numba

                _compiled.append(numba.njit(_SIGNATURE, nogil=True, fastmath=False,
                                            error_model="numpy")(locate))
            except Exception:  # noqa: BLE001 - numba present but unable to compile
                _compiled.append(None)
        return _compiled[0]
