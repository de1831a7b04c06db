"""Data-driven control laws of seed 001 on the FFDL data model (no FMI, no train in here):
FFDL-MFAC, FFDL-ISMC (eqs. 17-27), FFDL-ISMPC (eqs. 52-75) and the GPC baseline.

Every law works in the scaled units of :mod:`controllers.common.ffdl` (outputs ``y`` a speed,
inputs ``u`` a force per unit mass; the defaults here, ours, are set for km/h and m/s^2, and
:func:`controllers.datadriven.emu_control.rescaled` converts them) and has one call per
sample::

    u = law.step(y, y_r, y_r_next, lo, hi)      # y(t), y_r(t), y_r(t+1), input box -> u(t)
    law.hold(y, u)                              # or: u(t) imposed from outside (holding brake)

``u`` is incremental (``u(t) = u(t-1) + du(t)``) and clipped to ``[lo, hi]``; the clipped input
is what the estimator remembers, so saturation does not wind up the data model.

Sliding surface (eq. 18) with ``e = y - y_r`` (eq. 17), ``E``, ``F`` the running sums of ``e``
and ``sig^alpha(e)`` (eqs. 19, 20)::

    s(t) = e(t) + k1 E(t-1) + b k2 F(t-1)

Equivalent control (eq. 24, ``Phi_2^-1`` replaced by the regularised inverse ``K``)::

    du_eq = K (s - k1 E(t) - b k2 F(t) - dd_hat(t) + y_r(t+1) - y(t) - Phi_1 dy(t))

ISMC adds ``du_sw = -K beta sat(s / Delta)`` (eq. 26 with the boundary layer of eq. 27).
ISMPC adds the first move of an ``N``-step MPC on ``s`` (eqs. 58-73)::

    S = Lambda s(t) + Theta U - Psi P_hat,    min ||S||^2 + theta ||U||^2

with ``Theta`` built from the current ``Phi_2`` at every stage (the paper's "parameter values
held over the horizon", remark 4), ``P_hat`` = the last ``p_hat`` (eq. 70) at every stage, and
the input box as constraints on the cumulated moves (``u(t-1) + du_eq + sum U``). The
unconstrained minimiser (eq. 72) is used when it meets them; otherwise DAQP solves the QP,
warm-started from the previous plan's duals (:class:`controllers.common.qp.DenseQP`).
As ``theta -> inf`` the MPC moves vanish (``|U| <= |Theta'(Lambda s - Psi P)| / theta``) and
ISMPC is its equivalent control alone (ISMC with ``beta = 0``). ``b`` (the Lipschitz constant
of assumption 2 in eq. 18) and ``theta`` are not given in the paper: see the defaults.

The sign of ``Psi P_hat``: eqs. 72, 73, 75 print ``Lambda s + Psi P_hat``; the proof of
theorem 3 (eq. 78, and eq. 83 after it) uses ``Lambda s - Psi P_hat``, which gives ``s(t+1) =
p_hat(t-1) + p(t) = dd(t) - dd_hat(t-1)``; under assumption 3 both signs keep ``|s(t+1)| <=
2 gamma``. They differ under model error, which is what ``p_hat`` mostly carries on a data
model: ``dd_hat`` (eq. 14) holds ``(Phi_2 - Phi_2_hat) du(t-1)``, ``r = (Phi_2 - Phi_2_hat) /
Phi_2_hat``. The moves of the ``du`` loop alone (``c`` the MPC's first-move gain on ``p_hat``) obey
``z^2 + r (1 + c) z - c r = 0`` with eq. 72's sign, stable for ``-1 < r < 1 / (1 + 2c)``, and
``z^2 + r (1 - c) z + c r = 0`` with eq. 78's, stable for ``-1 < r < 1 / c``: eq. 78's sign
tolerates the larger model error (tests/test_datadriven.py closes the ``s`` loop with a fixed
``Phi_2_hat = Phi_2 / (1 + r)`` and checks the order). The paper's start ``Phi_2(1) = 0.5``
is such a model error for a train whose ``Phi_2`` is larger. The default is eq. 78's
(``error_prediction = "eq78"``), eq. 72's is ``"eq72"``, ``"off"`` is ``P_hat = 0``.
ISMC's layer pulls ``s`` back by ``beta / Delta`` per sample and has no ``p_hat`` term.

Anti-windup (``anti_windup``, ours): the sums ``E``, ``F`` are not advanced at a sample where
every unit's input saturates in the direction the law asks for (the train cannot act
on the surface). ISMPC's QP keeps its moves inside the box, so its inputs stop *on* the bound:
an input within ``BOUND_TOL`` of its bound counts as saturated. Without it the sums wind up
over every power-limited stretch and the law overshoots after it. Freezing them when only
some units saturate would leave a steady error (the end units at their power limit while the
middle unit still has room). MFAC and GPC have no sums: their inputs are incremental on the
clipped input they remember, so they have nothing to wind up.

Null-space force sharing (``share_gain``, ours; every law has it, :func:`null_space_share`):
a fraction of the units' departure from their mean input is removed per sample within the
null space of the law's input gain (``Phi_2`` for the FFDL laws, the RLS model's ``B_1`` for
GPC), which moves only the force split between the units.

Defaults: every tunable parameter of a law (its gains, ``share_gain``, the FFDL laws'
``pinv_cutoff``) defaults to its pick by one protocol for every law
(``papers/seed001/tuning.py``, written to ``controllers/datadriven/tuned.py``); the
estimators (FFDL's ``mu``, ``lambda``, ``Phi(1)``; GPC's RLS) and the horizons are the
paper's. The classes' docstrings give the paper's values.

FFDL-MFAC (Xiong and Hou 2022, the paper's ref. 18), with weight ``delta`` and step ``rho``::

    du = rho (delta I + Phi_2' Phi_2)^-1 Phi_2' (y_r(t+1) - y(t) - Phi_1 dy(t))

The paper's ``mu = 1, lambda = 0.2`` of MFAC are read as the estimator's (eq. 16), ``delta``
as the control weight (``lambda`` in Hou's notation) and ``rho`` as the control step.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from controllers.common.ffdl import FfdlEstimator, FfdlParams, sig, truncated_gain
from controllers.common.gpc import Gpc, GpcParams
from controllers.common.qp import DenseQP
from controllers.datadriven.tuned import TUNED
from cosim.fmu.declare import Checked, group, param
from cosim.fmu.state import StatefulCore

TUNED_BY = "picked by papers/seed001/tuning.py, controllers/datadriven/tuned.py"


def tuned(law: str, cls: type, **fixed: Any) -> Any:
    """``cls`` (a parameter group) with ``fixed`` and ``law``'s picks of its fields."""
    names = {f.name for f in fields(cls)}
    return cls(**fixed, **{k: v for k, v in TUNED[law].items() if k in names})


class Law(StatefulCore):
    """Common part of the FFDL laws: estimator and last applied input."""

    state_fields = ("est", "u")

    def __init__(self, ffdl: FfdlParams, n: int, disturbance: bool) -> None:
        self.n = n
        self.est = FfdlEstimator(ffdl, n, disturbance=disturbance)
        self.u = np.zeros(n)

    def hold(self, y: np.ndarray, u: np.ndarray) -> None:
        """A sample where ``u`` is imposed: the data model follows without learning."""
        self.est.observe(y, adapt=False)
        self._apply(np.asarray(u, float))

    def _apply(self, u: np.ndarray) -> np.ndarray:
        self.est.applied(u)
        self.u = u
        return u


def null_space_share(u: np.ndarray, M: np.ndarray, K: np.ndarray, gain: float) -> np.ndarray:
    """The move removing the fraction ``gain`` of the units' departure from their mean input
    ``dev = u - mean(u)`` within the null space of the input block ``M`` (``K`` its
    regularised inverse): ``gain (dev - K M dev)``, to subtract from a law's move. It leaves
    the modelled outputs alone (``M`` of it is about zero) and moves only the force split
    between the units, which the couplers absorb (ours; not in the paper)."""
    dev = u - u.sum() / u.size
    return gain * (dev - K @ (M @ dev))


# -- FFDL-MFAC -------------------------------------------------------------------------------

@dataclass(frozen=True)
class MfacParams(Checked):
    """FFDL-MFAC (paper section 4.1, 3): Phi(1) = 0.52 I, mu = 1, lambda = 0.2, delta = 1,
    rho = 0.85; the tunable parameters default to their picks (module text)."""

    ffdl: FfdlParams = group(tuned("MFAC", FfdlParams, phi1_init=0.52, phi2_init=0.52), "")
    delta: float = param(TUNED["MFAC"]["delta"], "1", "delta: weight on the input move "
                         f"(the paper's 1 is for a scaling it does not give; {TUNED_BY})",
                         min=0.0)
    rho: float = param(TUNED["MFAC"]["rho"], "1", "rho: step size of the control law (the "
                       f"paper's 0.85; {TUNED_BY})", min=0.0, max=2.0)
    share_gain: float = param(TUNED["MFAC"]["share_gain"], "1", "force sharing: fraction of "
                              "the units' departure from their mean input removed per sample, "
                              "in the null space of Phi_2 (0: off, the paper's MFAC; not in "
                              f"the paper; {TUNED_BY})", min=0.0, max=1.0)


class Mfac(Law):
    def __init__(self, params: MfacParams, n: int) -> None:
        super().__init__(params.ffdl, n, disturbance=False)
        self.p = params

    def step(self, y, y_r, y_r_next, lo, hi) -> np.ndarray:
        est = self.est
        est.observe(y)
        Phi2 = est.input_block
        target = y_r_next - y - est.free_response()
        du = self.p.rho * np.linalg.solve(self.p.delta * np.eye(self.n) + Phi2.T @ Phi2,
                                          Phi2.T @ target)
        if self.p.share_gain > 0:
            gain = est.control_gain()
            du = du - null_space_share(self.u, gain.M, gain.K, self.p.share_gain)
        return self._apply(np.clip(self.u + du, lo, hi))


# -- integral sliding surface (eqs. 17-24) ---------------------------------------------------

@dataclass(frozen=True)
class SurfaceParams(Checked):
    """Integral sliding surface of eq. 18."""

    k1: float = param(0.5, "1", "k1: weight of the error sum E (eq. 18)", min=0.0, max=1.0)
    k2: float = param(2.0, "1", "k2: weight of the sum F of sig^alpha(e) (eq. 18)", min=0.0)
    b: float = param(0.01, "1", "b of eq. 18 (Lipschitz constant of assumption 2; not "
                     "given in the paper; for y in km/h, converted with output_scale)", min=0.0)
    alpha: float = param(0.65, "1", "alpha: exponent of sig^alpha (eq. 20)", min=1e-3,
                         max=0.999)
    share_gain: float = param(0.2, "1", "force sharing: fraction of the units' departure "
                              "from their mean force removed per sample, in the null space "
                              "of the laws' Phi_2 (0: off; not in the paper)", min=0.0,
                              max=1.0)
    disturbance_estimate: bool = param(True, description="use the one-step delay-estimate "
                                       "of the disturbance change (eq. 14) and p_hat (eq. 70); "
                                       "false: dd_hat = 0 (a diagnostic, not the paper's law)")
    common_integral: float = param(1.0, "1", "fraction of the units' departures from the "
                                   "mean of the sums E, F (eqs. 19, 20) removed per sample "
                                   "(1: every unit integrates the mean; 0: the paper's "
                                   "per-unit sums)", min=0.0, max=1.0)
    anti_windup: bool = param(True, description="hold the sums E, F (eqs. 19, 20) at a sample "
                              "where every unit's input is at the bound the law pushes it "
                              "to (false: the paper's sums, always advanced)")


class SlidingLaw(Law):
    """Integral sliding surface and equivalent control shared by ISMC and ISMPC."""

    state_fields = ("est", "u", "E", "F", "s")
    BOUND_TOL = 1e-9  # m/s2: an input this close to its bound counts as saturated

    def __init__(self, ffdl: FfdlParams, surface: SurfaceParams, n: int) -> None:
        super().__init__(ffdl, n, disturbance=surface.disturbance_estimate)
        self.surface = surface
        self.E = np.zeros(n)
        self.F = np.zeros(n)
        self.s = np.zeros(n)

    def equivalent(self, y, y_r, y_r_next) -> tuple[np.ndarray, np.ndarray, np.ndarray,
                                                     np.ndarray]:
        """Observe ``y(t)``; returns ``s(t)``, ``du_eq`` (eq. 24), the gain ``K`` and the
        candidate sums ``E(t)``, ``F(t)`` (committed by :meth:`_finish`)."""
        c = self.surface
        est = self.est
        est.observe(y)
        e = y - y_r
        bk2 = c.b * c.k2
        s = e + c.k1 * self.E + bk2 * self.F
        E = self.E + e
        F = self.F + sig(e, c.alpha)
        if c.common_integral > 0:  # the units' speed differences integrate to coupler stretch
            E = E - c.common_integral * (E - E.sum() / self.n)
            F = F - c.common_integral * (F - F.sum() / self.n)
        gain = est.control_gain()
        Phi2, K = gain.M, gain.K
        du_eq = K @ (s - c.k1 * E - bk2 * F - est.dd_hat + y_r_next - y - est.free_response())
        if c.share_gain > 0:
            du_eq = du_eq - null_space_share(self.u, Phi2, K, c.share_gain)
        self.s = s
        self._gain = gain
        self._next = (E, F)
        return s, du_eq, K, E

    def _finish(self, u_wanted: np.ndarray, lo, hi) -> np.ndarray:
        u = np.clip(u_wanted, lo, hi)
        # at or beyond the bound: ISMPC's QP returns moves on the bound itself (its box
        # constraints), ISMC's law goes beyond it; both are "pushed"
        tol = self.BOUND_TOL
        pushed = (((u_wanted >= hi - tol) & (self.s < 0))
                  | ((u_wanted <= lo + tol) & (self.s > 0)))
        if not (self.surface.anti_windup and np.all(pushed)):
            self.E, self.F = self._next
        return self._apply(u)

    def hold(self, y: np.ndarray, u: np.ndarray) -> None:
        super().hold(y, u)
        self.E = np.zeros(self.n)
        self.F = np.zeros(self.n)
        self.s = np.zeros(self.n)


# -- FFDL-ISMC (eqs. 24-27) ------------------------------------------------------------------

@dataclass(frozen=True)
class IsmcParams(Checked):
    """FFDL-ISMC (section 4.1, 2): Phi(1) = 0.5 I, mu = 1, lambda = 0.2, beta = 0.05, k1 =
    0.5, k2 = 2, alpha = 0.65; the tunable parameters default to their picks (module text)."""

    ffdl: FfdlParams = group(tuned("ISMC", FfdlParams), "")
    surface: SurfaceParams = group(tuned("ISMC", SurfaceParams), "")
    beta: float = param(TUNED["ISMC"]["beta"], "1", "beta: switching gain (eq. 25, units of "
                        f"y per sample; the paper's 0.05; {TUNED_BY})", min=0.0)
    boundary_layer: float = param(TUNED["ISMC"]["boundary_layer"], "1", "Delta: width of "
                                  "the saturation boundary layer replacing sgn (eq. 27, km/h; "
                                  f"converted to the units of y; not in the paper: {TUNED_BY})",
                                  min=1e-9)


class Ismc(SlidingLaw):
    def __init__(self, params: IsmcParams, n: int) -> None:
        super().__init__(params.ffdl, params.surface, n)
        self.p = params

    def step(self, y, y_r, y_r_next, lo, hi) -> np.ndarray:
        s, du_eq, K, _ = self.equivalent(y, y_r, y_r_next)
        sat = np.clip(s / self.p.boundary_layer, -1.0, 1.0)
        du_sw = -K @ (self.p.beta * sat)
        return self._finish(self.u + du_eq + du_sw, lo, hi)


# -- FFDL-ISMPC (eqs. 52-75) -----------------------------------------------------------------

@dataclass(frozen=True)
class IsmpcParams(Checked):
    """FFDL-ISMPC (section 4.1, 1): Phi(1) = 0.5 I, mu = 1, lambda = 0.2, k1 = 0.5, k2 = 2,
    alpha = 0.5, N = 10; the tunable parameters default to their picks (module text)."""

    ffdl: FfdlParams = group(tuned("ISMPC", FfdlParams), "")
    surface: SurfaceParams = group(tuned("ISMPC", SurfaceParams), "")
    horizon: int = param(10, "1", "N: prediction and control horizon (eq. 57)", min=1,
                         max=50, integer=True, name="N")
    theta: float = param(TUNED["ISMPC"]["theta"], "1", "theta: weight of ||U||^2 in J_2 "
                         f"(eq. 66; not given in the paper: {TUNED_BY}; for km/h and m/s2, "
                         "converted with the scaling)", min=0.0)
    constraints: str = param("qp", description='the input box in the MPC of eq. 67: "qp", '
                             "the constrained QP (DAQP) when the unconstrained minimiser "
                             'leaves the box; "clip": the unconstrained minimiser (eq. 72) '
                             "alone, its input clipped to the box like the other laws'",
                             choices=("qp", "clip"))
    error_prediction: str = param("eq78", description='P_hat of eqs. 70-72 (every stage k of '
                                  "the MPC's prediction adds k p_hat(t-1), p_hat(t-1) = "
                                  'dd_hat(t) - dd_hat(t-1)) with the sign of the law theorem 3 '
                                  'proves, "eq78" (Lambda s - Psi P_hat), or as eqs. 72, 73, 75 '
                                  'print it, "eq72" (+ Psi P_hat); "off": P_hat = 0 (a '
                                  'diagnostic)', choices=("eq78", "eq72", "off"))


P_HAT_SIGN = {"eq78": -1.0, "eq72": 1.0, "off": 0.0}


class Ismpc(SlidingLaw):
    state_fields = ("est", "u", "E", "F", "s", "warm_dual", "qp_solves", "qp_failures")

    def __init__(self, params: IsmpcParams, n: int) -> None:
        params.check()
        super().__init__(params.ffdl, params.surface, n)
        self.p = params
        self._p_hat_sign = P_HAT_SIGN[params.error_prediction]
        N = params.horizon
        tril = np.tril(np.ones((N, N)))
        # the QP in the cumulated moves z_k = sum_{j<=k} U_j (U = D z): the input box becomes
        # simple bounds on z and Theta U = (I (x) Phi_2) z (tril D = I)
        self.qp = DenseQP(N * n)
        diff = np.linalg.inv(tril)  # D
        self._move_weight = 2.0 * params.theta * np.kron(diff.T @ diff, np.eye(n))
        self._eye_N = np.eye(N)
        self._tt = tril.T @ tril  # Theta'Theta = kron(tril'tril, Phi_2'Phi_2)
        self._tt_eig, self._tt_vec = np.linalg.eigh(self._tt)
        self._eye = np.eye(N * n)
        self._zero_dual = np.zeros(N * n)
        self._stages = np.arange(1.0, N + 1)[:, None]
        self.warm_dual = np.zeros(N * n)
        self.qp_solves = 0
        self.qp_failures = 0

    def mpc_moves(self, s: np.ndarray, lo_cum: np.ndarray, hi_cum: np.ndarray) -> np.ndarray:
        """``U`` (N, n) minimising eq. 67 under ``lo_cum <= sum_{j<=k} U_j <= hi_cum``.

        The unconstrained minimiser (eq. 72) is taken when it satisfies the constraints (it is
        then the QP's solution); otherwise the QP is solved by DAQP, warm-started."""
        n, N = self.n, self.p.horizon
        gain = self._gain  # the truncated block of equivalent() and its SVD
        Phi2 = gain.M
        # S = Lambda s + Theta U -/+ Psi P_hat; stage k (1..N) of the free part: s -/+ k p_hat
        p_hat = self._p_hat_sign * self.est.p_hat
        offset = s + self._stages * p_hat
        tails = np.cumsum(offset[::-1], axis=0)[::-1]  # sum_{k >= j} offset_k
        grad = tails @ Phi2  # Theta' (Lambda s + Psi P) as (N, n)
        # unconstrained minimiser (eq. 72) in the eigenvectors of the Kronecker factors of
        # Theta'Theta = tt (x) Phi_2'Phi_2 (Phi_2'Phi_2 = V diag(sv^2) V'): with X (N, n),
        # (tt (x) P'P + theta I) vec X = vec(tt X P'P + theta X) is diagonal in Q' X V. The
        # rows of grad lie in the span of V, so directions outside it get no move.
        Q, W = self._tt_vec, gain.Vt.T
        den = self._tt_eig[:, None] * (gain.sv * gain.sv)[None, :] + self.p.theta
        inv = np.divide(1.0, den, out=np.zeros_like(den), where=den > 1e-12)
        X = -(Q @ (((Q.T @ grad) @ W) * inv) @ gain.Vt)
        cum = np.cumsum(X, axis=0)
        if self.p.constraints == "clip" or ((cum >= lo_cum).all() and (cum <= hi_cum).all()):
            x, dual = X.ravel(), self._zero_dual
        else:
            # J = sum_k ||offset_k + Phi_2 z_k||^2 + theta ||D z||^2, lo_cum <= z_k <= hi_cum
            PtP = Phi2.T @ Phi2
            H = (self._eye_N[:, None, :, None] * PtP[None, :, None, :]).reshape(N * n, N * n)
            H = 2.0 * H + self._move_weight
            lo_all = np.broadcast_to(lo_cum, (N, n)).ravel()
            hi_all = np.broadcast_to(hi_cum, (N, n)).ravel()
            z, dual, _ = self.qp.solve(H, 2.0 * (offset @ Phi2).ravel(), lo_all, hi_all,
                                       self.warm_dual)
            zm = z.reshape(N, n)
            x = np.concatenate([zm[:1], np.diff(zm, axis=0)]).ravel()
            self.qp_solves += 1
            if not np.all(np.isfinite(x)):
                self.qp_failures += 1
                self.warm_dual = np.zeros(N * n)
                return np.zeros((N, n))
        # warm start of the next solve: the plan's active constraints shifted by one stage
        self.warm_dual = np.concatenate([dual[n:], np.zeros(n)])
        return x.reshape(N, n)

    def step(self, y, y_r, y_r_next, lo, hi) -> np.ndarray:
        s, du_eq, _, _ = self.equivalent(y, y_r, y_r_next)
        base = self.u + du_eq
        U = self.mpc_moves(s, lo - base, hi - base)
        return self._finish(base + U[0], lo, hi)


# -- GPC -------------------------------------------------------------------------------------

# the seed-001 GPC's p_max: far above any trace its RLS reaches (seed-001 runs: at most 2.5e12
# on the smooth rows, 1.4e7 on white; results equal to p_max = inf), so the covariance is not
# bounded, as in the paper; finite, so the FMU's XML start value stays a plain number
NO_COVARIANCE_BOUND = 1e300


@dataclass(frozen=True)
class GpcLawParams(Checked):
    """GPC baseline (section 4.1, 4): Ny = 3, Nu = 2, forgetting factor 0.9, the paper's
    textbook RLS: no bound on the covariance (``p_max`` = ``NO_COVARIANCE_BOUND``, never
    reached; the shared core's 1e4, ours, is a safeguard the paper does not have, README
    seed 001). The control weight (not in the paper) and the force sharing's gain are
    picked by the protocol every law gets (``papers/seed001/tuning.py``)."""

    gpc: GpcParams = group(tuned("GPC", GpcParams, p_max=NO_COVARIANCE_BOUND), "")
    share_gain: float = param(TUNED["GPC"]["share_gain"], "1", "force sharing: fraction of "
                              "the units' departure from their mean input removed per sample, "
                              "in the null space of the RLS model's B_1 (0: off, the paper's "
                              f"GPC; not in the paper; {TUNED_BY})", min=0.0, max=1.0)


SHARE_INVERSE = FfdlParams()  # the regularised inverse of B_1 for GPC's force sharing


class GpcLaw(StatefulCore):
    """:class:`controllers.common.gpc.Gpc` behind the common law interface; the reference
    over the horizon is extrapolated linearly from ``y_r(t)`` and ``y_r(t+1)``."""

    state_fields = ("gpc", "u")

    def __init__(self, params: GpcLawParams, n: int) -> None:
        self.p = params
        self.n = n
        self.gpc = Gpc(params.gpc, n)
        self.u = np.zeros(n)

    def step(self, y, y_r, y_r_next, lo, hi) -> np.ndarray:
        self.gpc.observe(y)
        j = np.arange(1, self.p.gpc.Ny + 1)[:, None]
        refs = np.maximum(y_r + j * (y_r_next - y_r), 0.0) * np.ones((1, self.n))
        u = self.gpc.plan(refs)
        if self.p.share_gain > 0:
            # GPC works in km/h and m/s2, the units the FFDL inverse's defaults are set for
            gain = truncated_gain(self.gpc.input_gain(), SHARE_INVERSE.pinv_regularisation,
                                  SHARE_INVERSE.pinv_cutoff)
            u = u - null_space_share(self.u, gain.M, gain.K, self.p.share_gain)
        self.u = np.clip(u, lo, hi)
        self.gpc.applied(self.u)
        return self.u

    def hold(self, y: np.ndarray, u: np.ndarray) -> None:
        self.gpc.observe(y, adapt=False)
        self.gpc.applied(u)
        self.u = np.asarray(u, float)
