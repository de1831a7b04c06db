"""MIMO full-form dynamic linearisation (FFDL) data model and its pseudo-Jacobian estimator
(seed 001 eqs. 8-16), shared by the data-driven controllers (MFAC, ISMC, ISMPC).

Data model (eq. 9 / eq. 13), ``n`` outputs and ``n`` inputs, pseudo-orders ``L_y``, ``L_u``::

    dH(t) = [dy(t); ...; dy(t-L_y+1); du(t); ...; du(t-L_u+1)]          (eq. 8)
    dy(t+1) = Phi(t) dH(t) + dd(t),   Phi = [Phi_1 ... Phi_{L_y+L_u}]     (eqs. 9, 13)

``Phi_{L_y+1}`` (called ``Phi_2`` in the paper's ``L_y = L_u = 1`` notation) is the block that
multiplies ``du(t)``: the input gain the control laws invert.

Estimator (eq. 16, projection algorithm minimising eq. 15, in the form the paper analyses in
eq. 30: the innovation is the model's a-priori error, without ``dd_hat``)::

    eps(t)  = dy(t) - Phi(t-1) dH(t-1)
    Phi(t)  = Phi(t-1) + lambda eps(t) dH(t-1)' / (mu + ||dH(t-1)||^2)

Disturbance delay-estimate (eq. 14, as printed, with ``Phi(t-1)``): ``dd_hat(t) = dy(t) -
Phi(t-1) dH(t-1)``, the part of the last output change the model does not explain, used as the
estimate of ``dd(t)`` (assumption 3: the disturbance changes little between samples). The paper
also puts ``dd_hat(t)`` into eq. 16; taken literally that innovation is identically zero and
``Phi`` never moves, while its proof of boundedness (eqs. 30-32) uses the innovation above.
``innovation_dd_hat = true`` is the other way out, used here before (a diagnostic, not the
paper's): ``eps(t) = dy(t) - dd_hat(t-1) - Phi(t-1) dH(t-1)`` and eq. 14 with the updated
``Phi(t)``. That innovation is a *difference* of a-priori errors, so it only sees changes of
``dH``: on the train (smooth ``dy``, small ``du``) ``Phi_1`` stayed near its start ``0.5 I``
(true ``~I``) for about 1000 s, and ``dd_hat`` carried the model error ``(I - Phi_1) dy(t-1)``,
half of every speed change (unbiased on a ramp disturbance, though: the test keeps that).
``p(t) = dd(t) - dd_hat(t)`` (eq. 41) is the estimation error the sliding-mode laws must absorb;
its one-step estimate is ``p_hat(t-1) = dd_hat(t) - dd_hat(t-1)`` (eq. 70). With ``disturbance
= False`` (plain FFDL-MFAC) ``dd_hat = 0``.

Reset condition (Hou's FFDL-MFAC): ``Phi`` is not updated while ``||dH(t-1)|| <= excitation``
(no information), and returns to ``Phi(1)`` when a diagonal entry of the input block becomes
smaller than ``reset_threshold`` (or changes sign), which keeps the control direction known.

Scaling (what makes ``Phi(1) = 0.5 I`` and ``mu = 1`` meaningful; ours, the seed-001 FMUs'
``output_scale``, ``input_scale``): here outputs are speeds and inputs forces per unit mass,
in units of the caller's choice. With ``y`` in km/h (``y = 3.6 v``) and ``u`` in m/s^2
(``u_i = F_i / m``, ``m`` the mean mass of a power unit), a free unit sampled at ``T`` has
``dy(t+1) = dy(t) + 3.6 T du(t)``: ``Phi_1 = I`` and ``Phi_2 = 3.6 T I = 0.72 I`` at ``T = 0.2
s``, so the paper's ``0.5 I`` is a start of the right sign and size; scaling ``y`` and ``u`` by
the same factor keeps ``Phi`` and changes only ``||dH||^2`` against ``mu`` (the step of eq. 16
is ``lambda ||dH||^2 / (mu + ||dH||^2)``). The seed-001 FMUs sample at 1 s with ``y`` in m/s
and ``u`` in m/s^2, where ``Phi_2 = T I = I`` (:mod:`controllers.datadriven.emu_control`).
The stiff couplers make the true ``Phi_2`` of the 3-unit train close to rank one (every
unit's force moves all speeds), so the control laws invert it with the regularised pseudo-inverse
:func:`regularised_pinv`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from cosim.fmu.declare import Checked, param
from cosim.fmu.state import StatefulCore

KMH_PER_MPS = 3.6


def regularised_pinv(M: np.ndarray, eps: float) -> np.ndarray:
    """``(M'M + eps I)^-1 M'``: the Tikhonov-regularised inverse of a nearly singular gain.

    Directions with singular value ``sigma >> sqrt(eps)`` are inverted (``1/sigma``), weak ones
    are damped (``sigma / (sigma^2 + eps)``) instead of amplified."""
    n = M.shape[1]
    return np.linalg.solve(M.T @ M + eps * np.eye(n), M.T)


class TruncatedGain(NamedTuple):
    """:func:`truncated_gain`: ``M_r = U_r diag(sv) V_r'``, ``K``, and ``sv``, ``V_r'``."""

    M: np.ndarray
    K: np.ndarray
    sv: np.ndarray
    Vt: np.ndarray


def truncated_gain(M: np.ndarray, eps: float, cutoff: float) -> TruncatedGain:
    """``M`` without its singular directions weaker than ``cutoff`` times the strongest
    (``M_r = U_r S_r V_r'``) and its regularised inverse
    ``K = V_r diag(sigma / (sigma^2 + eps)) U_r'``.

    Seed 001's train: the couplers (Table 1: k = 2e7 N/m, d = 5e6 N s/m) settle a force moved
    between units within about 0.1 s, so over a 0.2 s sample every unit's force moves every
    unit's speed alike and the input block of ``Phi`` is nearly rank one (condition number
    about 40). Its weak directions (force differences between units) act on nothing but the
    coupler stretch; inverting them (eqs. 24, 25, 72 invert ``Phi_2``) turns the noise in the
    speed differences into force differences of 100-200 kN between units. ``cutoff = 0``
    keeps every direction (then ``K`` is :func:`regularised_pinv`)."""
    U, sv, Vt = np.linalg.svd(M)
    keep = sv >= cutoff * sv[0]
    U, sv, Vt = U[:, keep], sv[keep], Vt[keep]
    return TruncatedGain((U * sv) @ Vt, (Vt.T * (sv / (sv * sv + eps))) @ U.T, sv, Vt)


def sig(x: np.ndarray, alpha: float) -> np.ndarray:
    """``sig^alpha(x) = sgn(x) |x|^alpha`` elementwise (lemma 1)."""
    return np.sign(x) * np.abs(x) ** alpha


@dataclass(frozen=True)
class FfdlParams(Checked):
    """Estimator of the FFDL pseudo-Jacobian (eqs. 15, 16) in the scaled units above."""

    mu: float = param(1.0, "1", "mu: weight on the change of the Phi estimate (eq. 15)",
                      min=1e-9)
    step: float = param(0.2, "1", "lambda: step size of the Phi estimator (eq. 16; 0: fixed "
                        "Phi)", min=0.0, max=2.0, name="lambda")
    L_y: int = param(1, "1", "output pseudo-order L_y (eq. 8)", min=1, max=10,
                    integer=True)
    L_u: int = param(1, "1", "input pseudo-order L_u (eq. 8)", min=1, max=10,
                    integer=True)
    phi1_init: float = param(0.5, "1", "diagonal of Phi_1(1), the output blocks", min=0.0)
    phi2_init: float = param(0.5, "1", "diagonal of Phi_2(1), the input block "
                             "(units of y per unit of u)", min=1e-6)
    reset_threshold: float = param(0.01, "1", "reset Phi to Phi(1) when a diagonal entry of "
                                   "the input block falls below this (km/h per m/s2; the "
                                   "seed-001 core converts it with the scaling)", min=0.0)
    excitation: float = param(1e-6, "1", "no update while ||dH(t-1)|| is at most this "
                              "(km/h or m/s2; converted with the scaling)",
                              min=0.0)
    pinv_regularisation: float = param(1e-2, "1", "eps of the regularised inverse "
                                       "(Phi_2' Phi_2 + eps I)^-1 Phi_2' (for km/h per m/s2; "
                                       "converted with the scaling)", min=0.0)
    pinv_cutoff: float = param(0.5, "1", "the control laws drop the directions of Phi_2 "
                               "whose singular value is below this fraction of the largest "
                               "(force differences between stiffly coupled units; 0: keep "
                               "all)", min=0.0, max=1.0)
    innovation_dd_hat: bool = param(False, description="subtract the previous sample's "
                                    "dd_hat in the innovation of eq. 16 and evaluate eq. 14 "
                                    "with the updated Phi (a diagnostic; false: eqs. 30, 14 "
                                    "as printed)")


class FfdlEstimator(StatefulCore):
    """Pseudo-Jacobian ``Phi`` (n x n(L_y + L_u)) and disturbance delay-estimate of one plant.

    Call :meth:`observe` once per sample with the measured output ``y(t)`` (before choosing
    ``u(t)``), then :meth:`applied` with the input ``u(t)`` actually applied.
    """

    state_fields = ("phi", "y_prev", "dy_hist", "du_hist", "u_prev", "dH_prev", "dd_hat",
                    "dd_hat_prev", "resets", "started")

    def __init__(self, params: FfdlParams, n: int, disturbance: bool = True) -> None:
        params.check()
        self.p = params
        self.n = n
        self.disturbance = disturbance
        self.phi = self.initial_phi()
        self.y_prev = np.zeros(n)
        self.dy_hist = np.zeros((params.L_y, n))  # dy(t), dy(t-1), ... (newest first)
        self.du_hist = np.zeros((params.L_u, n))  # du(t-1), du(t-2), ... (newest first)
        self.u_prev = np.zeros(n)
        self.dH_prev = np.zeros(n * (params.L_y + params.L_u))
        self.dd_hat = np.zeros(n)
        self.dd_hat_prev = np.zeros(n)
        self.resets = 0
        self.started = False

    def initial_phi(self) -> np.ndarray:
        p, n = self.p, self.n
        blocks = [p.phi1_init * np.eye(n)] + [np.zeros((n, n))] * (p.L_y - 1)
        blocks += [p.phi2_init * np.eye(n)] + [np.zeros((n, n))] * (p.L_u - 1)
        return np.hstack(blocks)

    @property
    def input_block(self) -> np.ndarray:
        """``Phi_2``: the block of ``Phi`` multiplying ``du(t)``."""
        k = self.p.L_y * self.n
        return self.phi[:, k:k + self.n]

    def start(self, y: np.ndarray, u: np.ndarray) -> None:
        """First sample: no increments yet; ``u`` is the input held before the first sample."""
        self.y_prev = np.array(y, float)
        self.u_prev = np.array(u, float)
        self.started = True

    def observe(self, y: np.ndarray, adapt: bool = True) -> None:
        """New measurement ``y(t)``: update ``Phi`` (eq. 16) and ``dd_hat`` (eq. 14)."""
        y = np.asarray(y, float)
        if not self.started:
            self.start(y, self.u_prev)
            return
        p = self.p
        dy = y - self.y_prev
        self.y_prev = y
        dH = self.dH_prev  # dH(t-1)
        norm2 = float(dH @ dH)
        prior = self.phi @ dH  # eq. 14's prediction with Phi(t-1)
        if adapt and p.step > 0 and math.sqrt(norm2) > p.excitation:
            known = self.dd_hat if self.disturbance and p.innovation_dd_hat else 0.0
            eps = dy - known - prior
            self.phi = self.phi + p.step * np.outer(eps, dH) / (p.mu + norm2)
            diag = np.diag(self.input_block)
            if np.any(diag < p.reset_threshold):
                self.phi = self.initial_phi()
                self.resets += 1
        self.dd_hat_prev = self.dd_hat
        if not self.disturbance:
            self.dd_hat = np.zeros(self.n)
        else:
            self.dd_hat = dy - (self.phi @ dH if p.innovation_dd_hat else prior)
        self.dy_hist = np.vstack([dy, self.dy_hist[:-1]])

    def applied(self, u: np.ndarray) -> None:
        """The input ``u(t)`` applied at this sample (after saturation)."""
        u = np.asarray(u, float)
        du = u - self.u_prev
        self.u_prev = u
        self.du_hist = np.vstack([du, self.du_hist[:-1]])
        self.dH_prev = np.concatenate([self.dy_hist.ravel(), self.du_hist.ravel()])

    def free_response(self) -> np.ndarray:
        """``sum_{w != L_y+1} Phi_w dH_w(t)``: the predicted ``dy(t+1)`` with ``du(t) = 0``
        (``Phi_1 dy(t)`` for ``L_y = L_u = 1``)."""
        p, n = self.p, self.n
        older_du = self.du_hist[:-1].ravel() if p.L_u > 1 else np.zeros(0)
        k = p.L_y * n
        out = self.phi[:, :k] @ self.dy_hist.ravel()
        if older_du.size:
            out = out + self.phi[:, k + n:] @ older_du
        return out

    @property
    def p_hat(self) -> np.ndarray:
        """``p_hat(t-1) = dd_hat(t) - dd_hat(t-1)`` (eq. 70)."""
        return self.dd_hat - self.dd_hat_prev

    def inverse_gain(self) -> np.ndarray:
        """Regularised pseudo-inverse of ``Phi_2`` (replaces ``Phi_2^-1`` of eqs. 24-26)."""
        return self.control_gain()[1]

    def control_gain(self) -> TruncatedGain:
        """``(Phi_2r, K, sv, V')``: the input block the laws use (weak directions dropped,
        :func:`truncated_gain`) and its regularised pseudo-inverse (for ``Phi_2^-1`` of eqs.
        24-26 and ``Phi_2`` in ``Theta`` of eq. 64)."""
        return truncated_gain(self.input_block, self.p.pinv_regularisation,
                              self.p.pinv_cutoff)
