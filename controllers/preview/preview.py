"""Optimal preview speed-tracking controller of the heavy freight train (seed 002, eqs. 16-37).

Servo feedback on ``x0 = [e, Delta z]`` plus reference preview over the next ``M_R`` samples and
disturbance preview of the resistance ahead over ``M_d`` samples (gains:
:mod:`controllers.preview.design`). The controller measures the locomotive (head) speed ``v`` and
position ``s``; the servo's speed is ``v_f = (1 - w) v + w v_c`` (``mean_weight`` w, our
addition), ``v_c`` the train-mean speed of :class:`controllers.common.mean_observer.
MeanSpeedObserver` (the force balance of the whole train from the locomotive's demand and the
modelled air brake and resistance, slowly corrected toward ``v``), and the error
``e = v_ref(s) - v_f`` at the head position (w = 0: the head speed alone, the paper's one mass).

* State ``z = [v, a, u(k-l-1), ..., u(k-1)]``: ``v`` the fed-back ``v_f``, the traction
  acceleration ``a`` and the held inputs from the design model driven by the demands actually
  passed on (after the envelope of
  :meth:`controllers.common.freight_blending.FreightBlending.accel_limits`).
* Reference ahead: the times of the reference profile give where the reference is ``j T`` after
  the measured position; ``R(k + j)`` is the reference speed there.
* Disturbance ahead: ``d(k + j) = -(w_basic(R(k+j)) + w_add(s_j))`` per unit effective mass
  (eqs. 2-6, 17) from the nominal train on the route data the plant uses (grade, curve and
  tunnel averaged over the train length at the predicted head positions ``s_j``), and
  (``air_brake_preview``, our addition on the paper's eq. 34-37 reasoning: a known resistance
  ahead) minus the air-brake deceleration the shared blending's brake-pipe model predicts
  (the plant's model and nominal data, as the design model takes the plant's traction lag):
  commanded reduction held, the planned stop application at the sample the reference reaches
  its onset.
* ``u(k) = u(k-1) + Delta u(k)`` (m/s^2) goes to the shared blending (traction / ED / air brake):
  with ``air_brake_preview`` it is the locomotive's part (electric brake only while the air
  brake acts, no power braking) and ``accel_demand`` the train's demand ``u - a_air``; without,
  it is the train's demand and the blending trims the air brake with it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from controllers.common.freight_blending import BlendingParams, FreightTracker, tracker_outputs
from controllers.common.freight_tuning import tuned_param
from controllers.common.mean_observer import correction_time_param, mean_weight_param
from controllers.preview.design import DelayedModel, lag_delay_model, preview_gains
from cosim.fmu.c_text import ShippedValues, numbers_line
from cosim.fmu.declare import Checked, group, param, sample_time
from plants.route import ReferenceProfile, Route


@dataclass(frozen=True)
class PreviewParams(Checked):
    blending: BlendingParams = group(BlendingParams(), "")
    sample_time: float = sample_time(0.2)
    q_e: float = param(1.0, "1", "weight of the speed error (m/s)^2 in eq. (37)", min=1e-12)
    q_dz: float = param(0.0, "1", "weight of the state differences Delta z in eq. (37)",
                        min=0.0)
    h: float = tuned_param("Preview", "h", "1", "weight H of the input difference "
                           "(m/s^2)^2 in eq. (37)", min=1e-12)
    preview_steps: int = tuned_param("Preview", "M_R", "1", "reference preview M_R (samples)",
                                     min=0, max=10000, integer=True)
    disturbance_steps: int = tuned_param("Preview", "M_d", "1", "disturbance preview M_d "
                                         "(samples)", min=0, max=10000, integer=True)
    traction_delay: float = param(0.5, "s", "tau of the design model (eq. 15)", min=0.0)
    traction_time_constant: float = param(1.5, "s", "t_vb of the design model (eq. 15)",
                                          min=1e-6)
    air_brake_preview: bool = param(True, description="the air-brake deceleration is a "
                                    "previewed disturbance (the blending's brake-pipe model, "
                                    "its planned stop application included) and u the "
                                    "locomotive's part; off: u is the whole train's demand, the "
                                    "blending trims the air brake with it")
    mean_weight: float = mean_weight_param("Preview")
    observer_correction_time: float = correction_time_param()


class FreightPreview(FreightTracker):
    """Optimal preview servo (eqs. 33-35) + shared blending."""

    state_fields = (*FreightTracker.state_fields, "z", "z_prev", "u_prev", "d_prev")
    params_class = PreviewParams
    output_vars = tracker_outputs("preview control input u(k) = u(k-1) + Delta u(k)")

    def __init__(self, params: PreviewParams, profile: ReferenceProfile, route: Route) -> None:
        super().__init__(params, profile, route)
        p = params
        self.model = self.design_model()
        self.gains = preview_gains(self.model, p.q_e, p.q_dz, p.h, p.preview_steps,
                                   p.disturbance_steps)
        times = profile.times()
        finite = np.isfinite(times)
        self._t_pts, self._x_pts = times[finite], profile.x[finite]
        self._v2 = profile.v**2
        self._horizon = np.arange(max(p.preview_steps, p.disturbance_steps) + 1) * p.sample_time
        self.z: np.ndarray | None = None  # design-model state z(k) (v measured)
        self.z_prev: np.ndarray | None = None
        self.u_prev = 0.0  # m/s^2, u(k-1)
        self.d_prev: float | None = None  # m/s^2, d(k-1)

    #: the design settings written beside the gains, which the native FMU checks against its
    #: parameters (it refuses other ones)
    NATIVE_DESIGN = ("sample_time", "q_e", "q_dz", "h", "preview_steps", "disturbance_steps",
                     "traction_delay", "traction_time_constant")

    @classmethod
    def native_data(cls, identifier: str, shipped: ShippedValues) -> dict[str, str]:
        """The tracker's build-time data (:meth:`FreightTracker.native_data`) and
        ``resources/preview/default.gains``: the optimal preview servo's gains (eqs. 33-36,
        :func:`controllers.preview.design.preview_gains` on the design model) for the declared
        defaults of the design parameters: one ``key count values...`` line each for the
        design settings (:data:`NATIVE_DESIGN`) and ``F0`` (1 + n), ``FR`` (M_R) and ``Fd``
        (M_d + 1); %.17g via repr: exact."""
        p = PreviewParams()
        model = lag_delay_model(p.sample_time, p.traction_delay, p.traction_time_constant)
        g = preview_gains(model, p.q_e, p.q_dz, p.h, p.preview_steps, p.disturbance_steps)
        lines = ["# optimal preview gains for the default design of controllers.preview.preview",
                 *(numbers_line(key, [float(getattr(p, key))]) for key in cls.NATIVE_DESIGN),
                 numbers_line("F0", g.F0[0]), numbers_line("FR", g.FR),
                 numbers_line("Fd", g.Fd)]
        return {**super().native_data(identifier, shipped),
                "resources/preview/default.gains": "\n".join(lines) + "\n"}

    def design_model(self) -> DelayedModel:
        """Eq. (15)/(18) with the preview's design dead time and lag (the observer's too)."""
        p = self.p
        return lag_delay_model(p.sample_time, p.traction_delay, p.traction_time_constant)

    def ahead(self, s: float) -> tuple[np.ndarray, np.ndarray]:
        """Reference speeds ``R(k+j)`` and disturbances ``d(k+j)``, ``j = 0..max(M_R, M_d)``,
        at the head positions the reference reaches ``j T`` after the measured position."""
        t0 = np.interp(s, self._x_pts, self._t_pts)
        s_j = np.interp(t0 + self._horizon, self._t_pts, self._x_pts)
        s_j[0] = s
        R = np.sqrt(np.maximum(np.interp(s_j, self.profile.x, self._v2), 0.0))
        b = self.blending
        d = -b.basic_accel(R) - b.additional_accel(s_j)
        return R, d

    def accel_demand(self, t: float, v: float, s: float, a_res: float, lo: float,
                     hi: float) -> float:
        p, g, m = self.p, self.gains, self.model
        self.a_ref = self.profile.accel(s)
        R, d = self.ahead(s)
        R[0] = self.v_ref
        d[0] = -a_res
        air = np.zeros(0)
        if p.air_brake_preview:  # u is the locomotive's part: its envelope, air as disturbance
            air = self.air_ahead(t, s, R)
            if air.size:
                d -= air
            trac, ed = self.blending.model.traction_limits(max(v, 0.0))
            lo, hi = -ed / self.m_eff, (0.0 if self.blending.air_applied() else trac / self.m_eff)
        vf = self.v_feedback  # the head speed, or its blend with the observed mean
        if self.z is None:  # first sample: at rest in the model, no differences yet
            self.z = np.zeros(m.n)
            self.z_prev = self.z.copy()
            self.z[0] = self.z_prev[0] = vf
            self.d_prev = d[0]
        else:
            self.z = m.A @ self.z + m.B[:, 0] * self.u_prev + m.E[:, 0] * self.d_prev
            self.z[0] = vf
        x0 = np.concatenate(([self.v_ref - vf], self.z - self.z_prev))
        dR = np.diff(R[: p.preview_steps + 1])
        dd = np.diff(np.concatenate(([self.d_prev], d[: p.disturbance_steps + 1])))
        du = float(g.F0[0] @ x0 + g.FR @ dR + g.Fd @ dd)
        u = min(max(self.u_prev + du, lo), hi)
        self.z_prev = self.z.copy()
        self.u_prev = u
        self.d_prev = float(d[0])
        if not p.air_brake_preview:
            return u
        self.locomotive_demand = u
        return u - (float(air[0]) if air.size else 0.0)  # the train's demand, air included

    def air_ahead(self, t: float, s: float, R: np.ndarray) -> np.ndarray:
        """Air-brake deceleration (m/s^2, >= 0) over the samples ``k + j`` (at their midpoints,
        friction coefficient at the reference speeds ``R``): the blending's brake-pipe model
        (:meth:`controllers.common.freight_blending.FreightBlending.air_force_ahead`) with the
        commanded reduction held and, before a stop's planned application, that application at
        the sample the reference reaches its onset (the stage
        :meth:`~controllers.common.freight_blending.FreightBlending.planned_reduction` gives
        there). Empty while no air brake acts or is planned within the horizon."""
        b, T = self.blending, self.p.sample_time
        planned = None
        if not b.air_applied():
            onset, _ = b._onset_ahead(s)
            if not math.isfinite(onset):
                return np.zeros(0)
            t_s, t_on = np.interp([s, onset], self._x_pts, self._t_pts)
            lead = T * round(float(t_on - t_s) / T)
            if lead > self._horizon[-1] or onset < s:
                return np.zeros(0)
            v_on = self.profile.speed(onset)
            a_res = b.resistance_accel(v_on, onset)
            planned = (t + lead, b.planned_reduction(onset, v_on, a_res))
        times = t + self._horizon + 0.5 * T
        return b.air_force_ahead(t, times, R, planned) / self.m_eff
