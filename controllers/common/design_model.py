"""Discrete design models for predictive controllers; the project's one ZOH discretisation.

:func:`zoh` discretises any LTI system exactly (zero-order hold, matrix exponential);
:func:`dare` solves the discrete Riccati equation. Both keep their results in the on-disk design
cache (:mod:`cosim.fmu.disk_cache`): a further process gets the same floats without scipy.
:func:`brake_delay_model` builds the seed 000 delay-augmented model of eqs. (9)-(10)::

    x(k+1) = A x(k) + b du(k - l) + g a_r(k),   x = [a_c, u_prev, v, s]

``u_prev`` is the plant input of the previous sample (the paper's ``u(k-l)`` slot), the input
is the command increment ``du`` and the plant input over ``[k, k+1)`` is ``u_prev + du``.
Unlike the paper's printed A (Euler rows ``v += T a_c``, ``s += T v``) the v and s rows here come
from the exact ZOH of the continuous chain lag -> v -> s, so the model matches the plant's
response to piecewise-constant commands exactly. The resistance ``a_r`` enters through ``g``
(exact for ``a_r`` constant over the sample), which is the disturbance ``w = g a_r`` (eq. 9).
Sign convention of the plant: ``a_c = -c u`` in equilibrium (braking is negative).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cosim.fmu.disk_cache import cached_arrays, source_digest

_VERSION = source_digest(__file__)


def zoh(a_cont: np.ndarray, b_cont: np.ndarray,
        sample_time: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact zero-order-hold discretisation of ``dx/dt = A x + B u`` over ``sample_time`` (s).

    Returns ``(Ad, Bd)`` with ``Ad = e^{A T}``, ``Bd = int_0^T e^{A t} dt B`` (block exponential;
    kept in the design cache, :mod:`cosim.fmu.disk_cache`, so a further process needs no scipy).
    """
    a_cont = np.atleast_2d(np.asarray(a_cont, dtype=float))
    b_cont = np.asarray(b_cont, dtype=float)
    if b_cont.ndim == 1:
        b_cont = b_cont[:, None]
    n, m = a_cont.shape[0], b_cont.shape[1]
    if a_cont.shape != (n, n) or b_cont.shape[0] != n:
        raise ValueError(f"zoh: A {a_cont.shape} and B {b_cont.shape} do not fit")
    if not sample_time > 0:
        raise ValueError(f"zoh: sample_time = {sample_time} must be > 0")
    block = np.zeros((n + m, n + m))
    block[:n, :n] = a_cont
    block[:n, n:] = b_cont

    def exponential() -> tuple[np.ndarray]:
        from scipy.linalg import expm

        return (expm(block * sample_time),)

    phi, = cached_arrays("zoh", _VERSION, [block, float(sample_time)], exponential)
    return phi[:n, :n], phi[:n, n:]


def dare(a: np.ndarray, b: np.ndarray, q: np.ndarray, r: np.ndarray) -> np.ndarray:
    """Stabilising solution P of the discrete algebraic Riccati equation
    ``A'PA - P - A'PB (R + B'PB)^-1 B'PA + Q = 0`` (scipy's ``solve_discrete_are``, kept in the
    design cache like :func:`zoh`)."""
    def solve() -> tuple[np.ndarray]:
        from scipy.linalg import solve_discrete_are

        return (solve_discrete_are(a, b, q, r),)

    p, = cached_arrays("dare", _VERSION, [np.atleast_2d(a), np.atleast_2d(b), np.atleast_2d(q),
                                          np.atleast_2d(r)], solve)
    return p


def delay_samples(delay: float, sample_time: float) -> int:
    """``l = Td / T`` (eq. 9); the dead time must be a whole number of samples."""
    ratio = delay / sample_time
    steps = int(round(ratio))
    if steps < 0 or abs(ratio - steps) > 1e-9:
        raise ValueError(f"brake_delay = {delay} s is not a whole number of samples "
                         f"of sample_time = {sample_time} s")
    return steps


# indices of the design state x = [a_c, u_prev, v, s]
A_C, U_PREV, V, S = 0, 1, 2, 3


@dataclass(frozen=True)
class DesignModel:
    """Delay-augmented design model of eq. (9): ``x+ = A x + b du + g a_r``; ``l`` delay samples."""

    A: np.ndarray  # (4, 4)
    b: np.ndarray  # (4,)
    g: np.ndarray  # (4,), response to a constant resistance acceleration a_r (m/s^2)
    delay_steps: int
    sample_time: float  # s
    brake_gain: float  # c, m/s^2 per %

    @property
    def n(self) -> int:
        return self.A.shape[0]

    def step(self, x: np.ndarray, du: float, a_r: float = 0.0) -> np.ndarray:
        return self.A @ x + self.b * du + self.g * a_r

    def step_command(self, x: np.ndarray, u: float, a_r: float = 0.0) -> np.ndarray:
        """One sample with the plant input ``u`` (%), i.e. ``du = u - u_prev``."""
        return self.step(x, u - x[U_PREV], a_r)


def brake_delay_model(brake_gain: float, brake_time_constant: float, brake_delay: float,
                      sample_time: float, euler: bool = False) -> DesignModel:
    """Model of eq. (9)-(10) from the plant parameters c (m/s^2 per %), tau (s), Td (s), T (s).

    ``euler``: the paper's printed rows for v and s (eq. 9: ``v+ = v + T a_c - T a_r``,
    ``s+ = s + T v``) instead of the exact ZOH ones; the lag row is exact either way.
    """
    if not brake_time_constant > 0:
        raise ValueError(f"brake_time_constant = {brake_time_constant} must be > 0")
    tau, c = brake_time_constant, brake_gain
    # continuous chain z = [a_c, v, s], inputs [u (%), a_r (m/s^2)]
    a3 = np.array([[-1.0 / tau, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    b3 = np.array([[-c / tau, 0.0], [0.0, -1.0], [0.0, 0.0]])
    ad, bd = zoh(a3, b3, sample_time)
    bu, br = bd[:, 0], bd[:, 1]
    idx = [A_C, V, S]
    a = np.zeros((4, 4))
    a[np.ix_(idx, idx)] = ad
    a[idx, U_PREV] = bu  # the previous input persists when du = 0
    a[U_PREV, U_PREV] = 1.0
    b = np.zeros(4)
    b[idx] = bu
    b[U_PREV] = 1.0
    g = np.zeros(4)
    g[idx] = br
    if euler:
        T = sample_time
        a[V, :] = 0.0
        a[S, :] = 0.0
        a[V, [A_C, V]] = T, 1.0
        a[S, [V, S]] = T, 1.0
        b[V] = b[S] = 0.0
        g[V], g[S] = -T, 0.0
    return DesignModel(a, b, g, delay_samples(brake_delay, sample_time), sample_time, c)
