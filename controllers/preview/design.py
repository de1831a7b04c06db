"""Design of the optimal preview servo for a plant with a lagged, delayed input (seed 002).

Design model (eq. 18, per unit effective mass): ``dv/dt = a + d``, ``t_vb da/dt + a = u(t - tau)``
(eq. 15), ``u`` the acceleration command, ``d = -F_r / (M (1 + gamma))`` the resistance as a
disturbance (eq. 17). Sampled exactly with a zero-order hold at ``T`` (any ``tau``: with
``tau = l T + m``, ``0 <= m < T``, the first ``m`` of a sample sees ``u(k - l - 1)``, the rest
``u(k - l)``), the input delay is removed by carrying the held inputs as states: ``z = [v, a,
u(k-l-1), ..., u(k-1)]``, ``z(k+1) = A z(k) + B u(k) + E d(k)`` (eq. 29, delay-free).

Difference operator ``Delta x(k) = x(k) - x(k-1)`` (eq. 22) on the state, input, reference and
disturbance gives the error system (eqs. 30-32) with ``x0 = [e, Delta z]``, ``e = R - C z``::

    x0(k+1) = Phi x0(k) + G_u Delta u(k) + G_R Delta R(k+1) + G_d Delta d(k)
    Phi = [[1, -C A], [0, A]], G_u = [-C B; B], G_R = [1; 0], G_d = [-C E; E]

Cost (eq. 37) ``sum x0' Q x0 + Delta u' H Delta u``, ``Q = diag(q_e, q_dz I)``. ``P`` solves the
DARE (eq. 36) of ``(Phi, G_u)``; the control (eqs. 33-35) is::

    Delta u(k) = F0 x0(k) + sum_{j=1}^{M_R} F_R(j) Delta R(k+j)
                 + sum_{j=0}^{M_d} F_d(j) Delta d(k+j)
    F0 = -(H + G_u' P G_u)^-1 G_u' P Phi,   xi = Phi + G_u F0
    F_R(j) = -(H + G_u' P G_u)^-1 G_u' (xi')^(j-1) P G_R
    F_d(j) = -(H + G_u' P G_u)^-1 G_u' (xi')^j P G_d

This is the reduced-order solution of the Riccati equation of the enlarged system (eqs. 27-28,
state ``[x0, Delta R(k+1..k+M_R)]``): its gain is ``[F0, F_R(1..M_R)]`` (tested), computed from
the DARE of ``x0`` only. The paper prints ``(xi')^(j-1)`` also for ``F_d``; with ``Delta d(k)``
acting on ``x0(k+1)`` (eq. 32) the exponent is ``j``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from controllers.common.design_model import dare, zoh


@dataclass(frozen=True)
class DelayedModel:
    """Sampled delay-free model ``z(k+1) = A z + B u + E d``, ``y = C z`` (speed)."""

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    E: np.ndarray
    delay_steps: int  # l = floor(tau / T)

    @property
    def n(self) -> int:
        return self.A.shape[0]


def lag_delay_model(T: float, tau: float, t_vb: float) -> DelayedModel:
    """Exact ZOH sampling of eq. (18) with input delay ``tau`` (s), lag ``t_vb`` (s), step ``T``."""
    if not (T > 0 and tau >= 0 and t_vb > 0):
        raise ValueError(f"need T > 0, tau >= 0, t_vb > 0 (got {T}, {tau}, {t_vb})")
    Ac = np.array([[0.0, 1.0], [0.0, -1.0 / t_vb]])
    Bc = np.array([[0.0], [1.0 / t_vb]])
    Ec = np.array([[1.0], [0.0]])
    lag = int(np.floor(tau / T + 1e-12))
    m = max(tau - lag * T, 0.0)
    Phi, _ = zoh(Ac, Bc, T)
    _, Ed = zoh(Ac, Ec, T)
    Phi_rest, Gamma0 = zoh(Ac, Bc, T - m)  # u(k - l) over the last T - m
    _, Gm = zoh(Ac, Bc, m) if m > 0 else (None, np.zeros((2, 1)))
    Gamma1 = Phi_rest @ Gm  # u(k - l - 1) over the first m
    nh = lag + 1  # held inputs u(k-l-1) .. u(k-1)
    n = 2 + nh
    A = np.zeros((n, n))
    B = np.zeros((n, 1))
    A[:2, :2] = Phi
    A[:2, 2:3] += Gamma1  # u(k-l-1)
    if lag == 0:
        B[:2] += Gamma0  # u(k) itself acts after the fraction m
    else:
        A[:2, 3:4] += Gamma0  # u(k-l)
    for i in range(2, n - 1):  # shift register of held inputs
        A[i, i + 1] = 1.0
    B[n - 1, 0] = 1.0  # u(k) becomes u((k+1)-1)
    C = np.zeros((1, n))
    C[0, 0] = 1.0
    E = np.zeros((n, 1))
    E[:2] = Ed
    return DelayedModel(A, B, C, E, lag)


@dataclass(frozen=True)
class PreviewGains:
    """Error system (eq. 32) and its optimal preview gains (eqs. 33-36)."""

    Phi: np.ndarray
    Gu: np.ndarray
    GR: np.ndarray
    Gd: np.ndarray
    P: np.ndarray
    F0: np.ndarray  # (1, 1 + n)
    FR: np.ndarray  # (M_R,), F_R(1..M_R)
    Fd: np.ndarray  # (M_d + 1,), F_d(0..M_d)


def error_system(model: DelayedModel) -> tuple[np.ndarray, ...]:
    """``(Phi, G_u, G_R, G_d)`` of eq. (32) for ``x0 = [e, Delta z]``."""
    A, B, C, E = model.A, model.B, model.C, model.E
    n = model.n
    Phi = np.zeros((1 + n, 1 + n))
    Phi[0, 0] = 1.0
    Phi[0, 1:] = -(C @ A)[0]
    Phi[1:, 1:] = A
    Gu = np.vstack((-(C @ B), B))
    GR = np.zeros((1 + n, 1))
    GR[0, 0] = 1.0
    Gd = np.vstack((-(C @ E), E))
    return Phi, Gu, GR, Gd


def preview_gains(model: DelayedModel, q_e: float, q_dz: float, h: float, m_r: int,
                  m_d: int) -> PreviewGains:
    """DARE (eq. 36) of the error system and the gains of eqs. (34)-(35)."""
    if not (q_e > 0 and q_dz >= 0 and h > 0 and m_r >= 0 and m_d >= 0):
        raise ValueError(f"need q_e > 0, q_dz >= 0, h > 0, M_R >= 0, M_d >= 0 "
                         f"(got {q_e}, {q_dz}, {h}, {m_r}, {m_d})")
    Phi, Gu, GR, Gd = error_system(model)
    Q = np.diag([q_e] + [q_dz] * model.n)
    H = np.array([[h]])
    P = dare(Phi, Gu, Q, H)
    K = np.linalg.solve(H + Gu.T @ P @ Gu, Gu.T)  # (H + G_u' P G_u)^-1 G_u'
    F0 = -K @ P @ Phi
    xi_t = (Phi + Gu @ F0).T
    FR, Fd = np.zeros(m_r), np.zeros(m_d + 1)
    vR, vd = P @ GR, P @ Gd  # (xi')^j P G
    for j in range(max(m_r, m_d + 1)):
        if j < m_r:
            FR[j] = -(K @ vR)[0, 0]  # F_R(j + 1)
        if j <= m_d:
            Fd[j] = -(K @ vd)[0, 0]  # F_d(j)
        vR, vd = xi_t @ vR, xi_t @ vd
    return PreviewGains(Phi, Gu, GR, Gd, P, F0, FR, Fd)
