"""Speed-tracking PID for the heavy freight train, traction / ED / air-brake blending (seed 002).

The loop is :class:`controllers.pid.speed_pid.SpeedPid` (acceleration units) on the head speed and
position, with three feedforwards:

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
from pathlib import Path
from typing import Any

from controllers.common.freight_blending import BlendingParams, FreightBlending
from controllers.pid.speed_pid import SpeedPid, SpeedPidParams
from cosim.fmu.declare import Declared, Var, build, group, param
from cosim.fmu.state import StatefulCore
from plants.route import ReferenceProfile, Route, load_route, route_parameter, routes_dir_in


def default_pid() -> SpeedPidParams:
    """Gains for the 10,676 t train at T = 0.2 s (m/s^2 per m/s, per m, jerk limit m/s^3)."""
    return SpeedPidParams(kp=0.3, ki=0.01, kd=0.0, accel_min=-1.0, accel_max=1.0,
                          rate_limit=0.05, sample_time=0.2)


@dataclass(frozen=True)
class FreightPidParams:
    pid: SpeedPidParams = group(default_pid(), "")
    blending: BlendingParams = group(BlendingParams(), "")
    preview_time: float = param(2.0, "s", "look-ahead of the reference acceleration "
                                "feedforward", min=0.0)
    resistance_feedforward: bool = param(True, description="add the modelled running "
                                         "resistance to the demand")

    def check(self) -> None:
        self.pid.check()
        self.blending.check()
        if not self.preview_time >= 0:
            raise ValueError(f"preview_time = {self.preview_time} must be >= 0")


def load_tracked_route(values: dict[str, Any], data_dir: Path) -> Route:
    """The route named by the ``route`` parameter; it must carry a reference profile."""
    route = load_route(values["route"], routes_dir_in(data_dir))
    if route.reference is None:
        raise ValueError(f"route {values['route']!r} has no reference profile")
    return route


class FreightPid(StatefulCore, Declared):
    """Sampled controller: ``compute(t, {"v", "s"})`` -> force demand and pipe reduction."""

    state_fields = ("pid", "blending", "v_ref", "a_ref")
    params_class = FreightPidParams
    setup_vars = (route_parameter("freight_20km", "its reference profile is tracked"),)
    input_vars = (
        Var.input("v", "m/s", "measured head speed"),
        Var.input("s", "m", "measured head position"),
    )
    output_vars = (
        Var.output("force_demand", "N", "locomotive force demand (> 0 traction, < 0 electric "
                   "brake)"),
        Var.output("pipe_reduction", "Pa", "brake-pipe reduction (0 = released)"),
        Var.output("accel_demand", "m/s2", "PID acceleration demand a_dem"),
        Var.output("v_ref", "m/s", "reference speed at the measured position"),
        Var.output("a_ref", "m/s2", "reference acceleration (with preview)"),
        Var.output("speed_error", "m/s", "v - v_ref"),
        Var.output("air_brake_estimate", "Pa", "modelled mean cylinder pressure"),
    )

    @classmethod
    def from_parameters(cls, values: dict[str, Any], data_dir: Path,
                        t0: float = 0.0) -> FreightPid:
        route = load_tracked_route(values, data_dir)
        return cls(build(FreightPidParams, values), route.reference, route)

    def __init__(self, params: FreightPidParams, profile: ReferenceProfile, route: Route) -> None:
        params.check()
        self.p = params
        self.profile = profile
        self.blending = FreightBlending(params.blending, profile, route)
        self.m_eff = self.blending.m_eff
        self.pid = SpeedPid(params.pid)
        self.v_ref = 0.0
        self.a_ref = 0.0

    def compute(self, t: float, inputs: dict[str, float]) -> tuple[dict[str, float], int]:
        p = self.p
        v, s = float(inputs["v"]), float(inputs["s"])
        speed = max(v, 0.0)
        self.v_ref = v_ref = self.profile.speed(s)
        self.a_ref = a_ref = self.profile.accel(s + speed * p.preview_time)
        a_res = self.blending.resistance_accel(speed, s) if p.resistance_feedforward else 0.0
        a_lo, a_hi = self.blending.accel_limits(speed)
        demand = self.pid.update(v, v_ref, a_ref, a_res, a_lo=a_lo, a_hi=a_hi)
        self.blending.blend(t, p.pid.sample_time, v, s, self.m_eff * demand, v_ref, a_ref, a_res)
        return self.outputs(), 1

    def outputs(self) -> dict[str, float]:
        b = self.blending
        return {"force_demand": b.force, "pipe_reduction": b.reduction,
                "accel_demand": self.pid.demand, "v_ref": self.v_ref, "a_ref": self.a_ref,
                "speed_error": -self.pid.error, "air_brake_estimate": b.pressure_estimate}
