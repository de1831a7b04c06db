"""Speed-tracking PID for the heavy freight train, traction / ED / air-brake blending (seed 002).

The loop is :class:`controllers.pid.speed_pid.SpeedPid` (acceleration units) on the fed-back
speed (the head's, blended with the observed train mean by ``mean_weight``: see
:class:`controllers.common.freight_blending.FreightTracker`) and the head position, with three
feedforwards:

* reference acceleration ``a_ref`` taken ``preview_time`` ahead (``s + v t_p``), so that the
  traction dead time and lag (eq. 15: 0.5 s + 1.5 s) do not make the train lag the profile —
  the preview idea of the paper, in its simplest form;
* running resistance per unit mass, from the nominal train model (basic resistance at ``v``,
  grade/curve/tunnel averaged over the train length at ``s``);
* the estimated air-brake force, so the electric brake only trims the air brake.

The force demand ``F = M (1 + gamma) a_dem`` goes through the shared traction / electric brake /
air brake blending (:mod:`controllers.common.freight_blending`): air brake only where the
electric brake is not enough, never traction against it, holding brake at the final stop.
"""

from __future__ import annotations

from dataclasses import dataclass

from controllers.common.freight_blending import BlendingParams, FreightTracker, tracker_outputs
from controllers.common.freight_tuning import tuned, tuned_param
from controllers.common.mean_observer import correction_time_param, mean_weight_param
from controllers.pid.speed_pid import SpeedPid, SpeedPidParams
from cosim.fmu.declare import Checked, group, param
from plants.route import ReferenceProfile, Route

PREVIEW_TIME = "look-ahead of the reference acceleration feedforward"


def preview_time_param() -> float:
    """The look-ahead ``t_p`` of the fuzzy PID's optional reference-acceleration feedforward
    (the PID's is tuned: :class:`FreightPidParams`)."""
    return param(2.0, "s", PREVIEW_TIME, min=0.0)


def default_pid() -> SpeedPidParams:
    """The tuned gains for the 10,676 t train at T = 0.2 s (m/s^2 per m/s, per m; PI: kd = 0),
    demand limits (m/s^2) and jerk limit (m/s^3)."""
    return SpeedPidParams(kp=tuned("PID", "kp"), ki=tuned("PID", "ki"), kd=0.0,
                          accel_min=-1.0, accel_max=1.0, rate_limit=0.05, sample_time=0.2)


@dataclass(frozen=True)
class FreightPidParams(Checked):
    pid: SpeedPidParams = group(default_pid(), "")
    blending: BlendingParams = group(BlendingParams(), "")
    preview_time: float = tuned_param("PID", "preview_time", "s", PREVIEW_TIME, min=0.0)
    resistance_feedforward: bool = param(True, description="add the modelled running "
                                         "resistance to the demand")
    mean_weight: float = mean_weight_param("PID")
    observer_correction_time: float = correction_time_param()


class FreightPid(FreightTracker):
    """Sampled controller: ``compute(t, {"v", "s"})`` -> force demand and pipe reduction."""

    state_fields = (*FreightTracker.state_fields, "pid")
    params_class = FreightPidParams
    output_vars = tracker_outputs("PID acceleration demand a_dem")

    def __init__(self, params: FreightPidParams, profile: ReferenceProfile, route: Route) -> None:
        super().__init__(params, profile, route)
        self.pid = SpeedPid(params.pid)

    @property
    def sample_time(self) -> float:
        return self.p.pid.sample_time

    def accel_demand(self, t: float, v: float, s: float, a_res: float, lo: float,
                     hi: float) -> float:
        p = self.p
        self.a_ref = a_ref = reference_feedforward(self.profile, v, s, p.preview_time)
        return self.pid.update(self.v_feedback, self.v_ref, a_ref,
                               a_res if p.resistance_feedforward else 0.0, a_lo=lo, a_hi=hi)


def reference_feedforward(profile: ReferenceProfile, v: float, s: float,
                          preview_time: float) -> float:
    """The reference acceleration ``preview_time`` ahead of the measured head,
    ``a_ref(s + v t_p)`` (m/s^2): the PID's feedforward, also the fuzzy PID's option."""
    return profile.accel(s + max(v, 0.0) * preview_time)
