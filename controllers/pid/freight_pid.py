"""Speed-tracking PID for the heavy freight train, traction / ED / air-brake blending (seed 002).

The loop is :class:`controllers.pid.speed_pid.SpeedPid` (acceleration units) on the head speed and
position, with three feedforwards:

* reference acceleration ``a_ref`` taken ``preview_time`` ahead (``s + v t_p``), so that the
  traction dead time and lag (eq. 15: 0.5 s + 1.5 s) do not make the train lag the profile —
  the preview idea of the paper, in its simplest form;
* running resistance per unit mass, from the nominal train model (basic resistance at ``v``,
  grade/curve/tunnel averaged over the train length at ``s``);
* the estimated air-brake force, so the electric brake only trims the air brake.

The force demand ``F = M (1 + gamma) a_dem`` goes to the locomotive (traction or electric brake,
within the HXD1 envelope at the measured speed). The air brake is used only when the electric
brake is not enough: it is applied when the planned braking (reference acceleration now or
``air_preview_time`` ahead, the air brake being slow, plus resistance) or, at an overspeed above
``overspeed``, the feedback demand ``F`` needs more than ``ed_share`` of the electric brake,
with a pipe reduction in ``reduction_step`` stages giving the missing force; it may then be
deepened, never partly released (Chinese 120 valves release directly), and is released fully
when the electric brake alone covers the demand with margin (``release_share``). Realistic
hold times: once applied it stays at least ``min_apply_time``; once released it is not
re-applied for ``min_release_time`` (auxiliary reservoirs recharge). While it is applied the
locomotive trims it, pulling against it where even the minimum reduction brakes too hard
(power braking, a heavy-haul practice for slack and speed control). The air-brake force
estimate runs the plant's brake-pipe model (propagation delays, eq. (9) filling) on the nominal
brake data of :class:`plants.freight.FreightParams`.
At the end of the profile (zero reference, speed under ``stop_speed``) it holds the train with
``hold_reduction``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from controllers.pid.speed_pid import SpeedPid, SpeedPidParams
from cosim.fmu.declare import Declared, Var, build, group, param
from cosim.fmu.state import StatefulCore
from plants.freight import FreightParams, FreightTrain, friction_coefficient
from plants.route import (
    GRAVITY,
    ReferenceProfile,
    Route,
    load_route,
    route_parameter,
    routes_dir_in,
)


def default_pid() -> SpeedPidParams:
    """Gains for the 10,676 t train at T = 0.2 s (m/s^2 per m/s, per m, jerk limit m/s^3)."""
    return SpeedPidParams(kp=0.3, ki=0.01, kd=0.0, accel_min=-1.0, accel_max=1.0,
                          rate_limit=0.05, sample_time=0.2)


@dataclass(frozen=True)
class FreightPidParams:
    pid: SpeedPidParams = group(default_pid(), "")
    train: FreightParams = field(default_factory=FreightParams)  # nominal model
    preview_time: float = param(2.0, "s", "look-ahead of the reference acceleration "
                                "feedforward", min=0.0)
    air_preview_time: float = param(6.0, "s", "look-ahead of the planned braking for the "
                                    "air-brake decision", min=0.0)
    resistance_feedforward: bool = param(True, description="add the modelled running "
                                         "resistance to the demand")
    ed_share: float = param(0.8, "1", "share of the electric brake used before the air brake "
                            "is applied", min=0.0, max=1.0)
    release_share: float = param(0.4, "1", "air brake released when the electric brake alone "
                                 "needs less than this share", min=0.0, max=1.0)
    min_apply_time: float = param(30.0, "s", "shortest air-brake application", min=0.0)
    min_release_time: float = param(60.0, "s", "shortest time released before a new "
                                    "application", min=0.0)
    reduction_step: float = param(10e3, "Pa", "pipe-reduction stage", min=1.0)
    overspeed: float = param(2.0 / 3.6, "m/s", "overspeed above which feedback may call the "
                             "air brake", min=0.0)
    stop_speed: float = param(0.3, "m/s", "below this speed at the end of the profile the "
                              "train is held", min=0.0)
    hold_reduction: float = param(100e3, "Pa", "pipe reduction holding the train at the final "
                                  "stop", min=0.0)

    def check(self) -> None:
        self.pid.check()
        self.train.check()
        for name in ("preview_time", "air_preview_time", "min_apply_time", "min_release_time",
                     "stop_speed", "hold_reduction"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"{name} = {getattr(self, name)} must be >= 0")
        if not 0 < self.release_share < self.ed_share <= 1:
            raise ValueError(f"need 0 < release_share ({self.release_share}) < ed_share "
                             f"({self.ed_share}) <= 1")
        if not self.reduction_step > 0:
            raise ValueError(f"reduction_step = {self.reduction_step} must be > 0")


class FreightPid(StatefulCore, Declared):
    """Sampled controller: ``compute(t, {"v", "s"})`` -> force demand and pipe reduction."""

    state_fields = ("pid", "reduction", "pressure_estimate", "changed_at", "force",
                    "v_ref", "a_ref", "brake_model_state")
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
        route = load_route(values["route"], routes_dir_in(data_dir))
        if route.reference is None:
            raise ValueError(f"route {values['route']!r} has no reference profile")
        return cls(build(FreightPidParams, values), route.reference, route)

    def __init__(self, params: FreightPidParams, profile: ReferenceProfile, route: Route) -> None:
        params.check()
        if profile.kind != "distance":
            raise ValueError("the freight PID needs a speed-distance reference profile")
        self.p = params
        self.profile = profile
        self.route = route
        self.model = FreightTrain(params.train, route)
        self.m_eff = float(self.model.m_eff.sum())
        self.weight = float(self.model.mass.sum() * GRAVITY)  # N
        self.brake_scale = float(self.model.brake_scale.sum())  # N per Pa per phi
        m = self.model  # sums of the basic-resistance coefficients (constants)
        self._res_sums = (float(m.res_a.sum()), float(m.res_b.sum()), float(m.res_c.sum()))
        self.pid = SpeedPid(params.pid)
        self.reduction = 0.0  # Pa, commanded pipe reduction
        self.pressure_estimate = 0.0  # Pa, modelled mean cylinder pressure
        self.changed_at = -math.inf  # s, time of the last apply/release
        self.force = 0.0  # N
        self.v_ref = 0.0
        self.a_ref = 0.0

    @property
    def brake_model_state(self) -> dict:
        return {"pressure": self.model.pressure.copy(),
                "history": [list(h) for h in self.model.brake_history]}

    @brake_model_state.setter
    def brake_model_state(self, state: dict) -> None:
        self.model.pressure = np.array(state["pressure"], dtype=float)
        self.model.brake_history = [list(h) for h in state["history"]]

    def resistance_accel(self, v: float, s: float) -> float:
        """Modelled running resistance per unit effective mass (m/s^2)."""
        a, b, c = self._res_sums
        basic = a + (b + c * v) * v
        extra = (self.route.additional.mean_over_scalar(s, self.model.train_length)
                 * self.weight / 1e3)
        return (basic + extra) / self.m_eff

    def air_force(self, pressure: float, v: float) -> float:
        """Air-brake force (N) of the whole train at a uniform cylinder pressure (Pa)."""
        return self.brake_scale * pressure * float(friction_coefficient(np.array(v)))

    def _reduction_for(self, force: float, v: float) -> float:
        """Smallest staged pipe reduction (Pa) whose air brake gives ``force`` (N)."""
        tp = self.p.train
        per_pa = self.air_force(1.0, v)
        need = force / per_pa / tp.max_cylinder_pressure * tp.full_service_reduction
        step = self.p.reduction_step
        return min(max(math.ceil(need / step) * step, tp.min_reduction),
                   tp.full_service_reduction)

    def compute(self, t: float, inputs: dict[str, float]) -> tuple[dict[str, float], int]:
        p = self.p
        T = p.pid.sample_time
        v, s = float(inputs["v"]), float(inputs["s"])
        speed = max(v, 0.0)
        self.v_ref = v_ref = self.profile.speed(s)
        self.a_ref = a_ref = self.profile.accel(s + speed * p.preview_time)
        a_res = self.resistance_accel(speed, s) if p.resistance_feedforward else 0.0
        trac, ed = self.model.traction_limits(speed)
        full_air = self.air_force(p.train.max_cylinder_pressure, speed)
        demand = self.pid.update(v, v_ref, a_ref, a_res, a_lo=-(ed + full_air) / self.m_eff,
                                 a_hi=trac / self.m_eff)
        force = self.m_eff * demand
        # planned braking (feedforward now and ahead) or an overspeed the ED brake cannot hold
        planned = self.m_eff * (min(a_ref, self.profile.accel(s),
                                    self.profile.accel(s + speed * p.air_preview_time)) + a_res)
        need = max(-planned, -force if v - v_ref > p.overspeed else 0.0)
        applied = self.reduction > 0.0
        since = t - self.changed_at
        holding = v_ref < p.stop_speed and self.profile.accel(s) <= 0.0 and v < p.stop_speed
        if holding:
            if self.reduction < p.hold_reduction:
                self.reduction, self.changed_at = p.hold_reduction, t
            force = 0.0
        elif applied:
            extra = need - p.ed_share * ed
            if extra > self.air_force(self.pressure_estimate, speed) and extra > 0:
                self.reduction = max(self.reduction, self._reduction_for(extra, speed))
            elif since >= p.min_apply_time and need < p.release_share * ed:
                self.reduction, self.changed_at = 0.0, t
        elif since >= p.min_release_time and need > p.ed_share * ed:
            self.reduction = self._reduction_for(need - p.ed_share * ed, speed)
            self.changed_at = t
        pressures = self.model.step_brakes(t, t + T, self.reduction)
        self.pressure_estimate = float(pressures.mean())
        if self.reduction > 0.0 and not holding:
            # the locomotive trims the (estimated) air brake: electric brake, or traction
            # against it where a minimum application is too strong (power braking)
            force = force + float(np.dot(self.model.brake_scale, pressures)
                                  * friction_coefficient(np.array(speed)))
        self.force = min(max(force, -ed), trac)
        return self.outputs(), 1

    def outputs(self) -> dict[str, float]:
        return {"force_demand": self.force, "pipe_reduction": self.reduction,
                "accel_demand": self.pid.demand, "v_ref": self.v_ref, "a_ref": self.a_ref,
                "speed_error": -self.pid.error, "air_brake_estimate": self.pressure_estimate}
