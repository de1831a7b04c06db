"""Sliding-mode speed tracking of the heavy freight train (seed 002 baseline, Fig. 10).

Designed on the nominal first-order model ``v(k+1) = v(k) + T (u(k) - a_res)`` (no traction lag:
the baseline ignores it, which is why it chatters on the real chain). Sliding variable on the
speed error ``e = v_ref - v_f`` (``v_f`` the fed-back speed of
:class:`controllers.common.freight_blending.FreightTracker`) with an integral term,
``sigma = e + lambda I``,
``I(k+1) = I(k) + T e(k)``, and Gao's discrete exponential reaching law
``sigma(k+1) = (1 - q T) sigma(k) - eps T sgn(sigma(k))`` give::

    u = a_ref + a_res + lambda e + q sigma + eps sgn(sigma)

``boundary_layer`` phi > 0 replaces ``sgn`` by ``sat(sigma / phi)``: inside the layer the law is
linear, ``sigma(k+1) = (1 - q T - eps T / phi) sigma(k)``, so on the design model sigma enters
the layer and decays in it without switching sign when ``(q + eps / phi) T < 1``; with ``sgn``
it switches sign about every sample, in a band of about ``eps T``. The demand goes to the
shared blending.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from controllers.common.freight_blending import BlendingParams, FreightTracker, tracker_outputs
from controllers.common.freight_tuning import tuned_param
from controllers.common.mean_observer import correction_time_param, mean_weight_param
from cosim.fmu.declare import Checked, group, param, sample_time
from plants.route import ReferenceProfile, Route


@dataclass(frozen=True)
class SlidingModeParams(Checked):
    blending: BlendingParams = group(BlendingParams(), "")
    sample_time: float = sample_time(0.2)
    lam: float = tuned_param("SMC", "lambda", "1/s", "lambda: integral weight of the "
                             "sliding variable", min=0.0)
    q: float = tuned_param("SMC", "q", "1/s", "exponential reaching rate q", min=0.0)
    eps: float = tuned_param("SMC", "eps", "m/s2", "switching gain eps of the reaching law",
                             min=0.0)
    boundary_layer: float = param(0.0, "m/s", "phi of sat(sigma / phi) (0: sgn, the paper's)",
                                  min=0.0)
    mean_weight: float = mean_weight_param("SMC")
    observer_correction_time: float = correction_time_param()

    def check_relations(self) -> None:
        if not self.q * self.sample_time < 1:
            raise ValueError(f"q T = {self.q * self.sample_time} must be in [0, 1)")


def switching(sigma: float, phi: float) -> float:
    """``sgn(sigma)``, or ``sat(sigma / phi)`` for a boundary layer ``phi > 0``."""
    if phi > 0:
        return max(-1.0, min(1.0, sigma / phi))
    return math.copysign(1.0, sigma) if sigma != 0 else 0.0


class FreightSlidingMode(FreightTracker):
    """Sliding-mode controller with exponential reaching law + shared blending."""

    state_fields = (*FreightTracker.state_fields, "integral", "sigma")
    params_class = SlidingModeParams
    output_vars = tracker_outputs("sliding-mode demand u")

    def __init__(self, params: SlidingModeParams, profile: ReferenceProfile,
                 route: Route) -> None:
        super().__init__(params, profile, route)
        self.integral = 0.0  # m, I(k)
        self.sigma = 0.0  # m/s

    def law(self, e: float, a_ref: float, a_res: float) -> float:
        """Sliding variable update and the reaching-law demand (m/s^2) for error ``e``."""
        p = self.p
        self.sigma = e + p.lam * self.integral
        return (a_ref + a_res + p.lam * e + p.q * self.sigma
                + p.eps * switching(self.sigma, p.boundary_layer))

    def accel_demand(self, t: float, v: float, s: float, a_res: float, lo: float,
                     hi: float) -> float:
        self.a_ref = self.profile.accel(s)
        e = self.v_ref - self.v_feedback
        u = self.law(e, self.a_ref, a_res)
        self.integral += self.sample_time * e
        return min(max(u, lo), hi)
