"""FMU wrapper of :class:`controllers.pid.freight_pid.FreightPid` (seed 002 baseline)."""

from __future__ import annotations

import dataclasses

from controllers.pid.freight_pid import FreightPid, FreightPidParams
from controllers.pid.speed_pid import SpeedPidParams
from controllers.pid.speed_pid_fmu import speed_pid_variables
from cosim.fmu.slave import CONTROLLER_TIMING_VARS, SampledControllerSlave, Var
from plants.route import load_route

_D = FreightPidParams()
_PID_NAMES = tuple(SpeedPidParams.__dataclass_fields__)
# the speed-PID gain variables, with the freight defaults
_PID_VARS = tuple(dataclasses.replace(v, start=getattr(_D.pid, v.name))
                  for v in speed_pid_variables(1) if v.name in _PID_NAMES)


class FreightPidFmu(SampledControllerSlave):
    """Freight speed PID with traction / electric brake / air brake blending (seed 002)."""

    default_experiment_stop_time = 100.0
    default_experiment_step = 0.2
    variables = (
        *_PID_VARS,
        Var("preview_time", "parameter", _D.preview_time, "s",
            "look-ahead of the reference acceleration feedforward", min=0.0),
        Var("air_preview_time", "parameter", _D.air_preview_time, "s",
            "look-ahead of the planned braking for the air-brake decision", min=0.0),
        Var("resistance_feedforward", "parameter", _D.resistance_feedforward, description=
            "add the modelled running resistance to the demand"),
        Var("ed_share", "parameter", _D.ed_share, "1",
            "share of the electric brake used before the air brake is applied", min=0.0,
            max=1.0),
        Var("release_share", "parameter", _D.release_share, "1",
            "air brake released when the electric brake alone needs less than this share",
            min=0.0, max=1.0),
        Var("min_apply_time", "parameter", _D.min_apply_time, "s",
            "shortest air-brake application", min=0.0),
        Var("min_release_time", "parameter", _D.min_release_time, "s",
            "shortest time released before a new application", min=0.0),
        Var("reduction_step", "parameter", _D.reduction_step, "Pa",
            "pipe-reduction stage", min=1.0),
        Var("overspeed", "parameter", _D.overspeed, "m/s",
            "overspeed above which feedback may call the air brake", min=0.0),
        Var("stop_speed", "parameter", _D.stop_speed, "m/s",
            "below this speed at the end of the profile the train is held", min=0.0),
        Var("hold_reduction", "parameter", _D.hold_reduction, "Pa",
            "pipe reduction holding the train at the final stop", min=0.0),
        Var("route", "parameter", "freight_20km", description=
            "bundled route name or route TOML path; its reference profile is tracked"),
        Var("v", "input", 0.0, "m/s", "measured head speed"),
        Var("s", "input", 0.0, "m", "measured head position"),
        Var("force_demand", "output", 0.0, "N",
            "locomotive force demand (> 0 traction, < 0 electric brake)"),
        Var("pipe_reduction", "output", 0.0, "Pa", "brake-pipe reduction (0 = released)"),
        Var("accel_demand", "output", 0.0, "m/s2", "PID acceleration demand a_dem"),
        Var("v_ref", "output", 0.0, "m/s", "reference speed at the measured position"),
        Var("a_ref", "output", 0.0, "m/s2", "reference acceleration (with preview)"),
        Var("speed_error", "output", 0.0, "m/s", "v - v_ref"),
        Var("air_brake_estimate", "output", 0.0, "Pa", "modelled mean cylinder pressure"),
        *CONTROLLER_TIMING_VARS,
    )

    def make_core(self) -> FreightPid:
        val = self.values
        pid = SpeedPidParams(**{k: val[k] for k in _PID_NAMES})
        names = [f.name for f in dataclasses.fields(FreightPidParams)
                 if f.name not in ("pid", "train")]
        params = FreightPidParams(pid=pid, **{k: val[k] for k in names})
        route = load_route(val["route"], self.resource_path("plants", "routes"))
        if route.reference is None:
            raise ValueError(f"route {val['route']!r} has no reference profile")
        return FreightPid(params, route.reference, route)
