"""FMU wrappers of :class:`controllers.pid.speed_pid.DistributedSpeedPid` for the EMU plants.

``EmuSpeedPid3`` drives ``Emu3`` (3 units), ``EmuSpeedPid8`` drives ``Emu8``. The reference is a
bundled profile name or a file (see :mod:`plants.route`), looked up by the measured head
position (speed-distance) or by time (speed-time).
"""

from __future__ import annotations

from typing import ClassVar

from controllers.pid.speed_pid import (
    DistributedSpeedPid,
    DistributedSpeedPidParams,
    SpeedPidParams,
)
from cosim.fmu.slave import CONTROLLER_TIMING_VARS, SampledControllerSlave, Var
from plants.route import load_reference

_D = SpeedPidParams()
_DD = DistributedSpeedPidParams(pid=_D, units=1, mass=1.0)


def speed_pid_variables(n: int) -> tuple[Var, ...]:
    """FMI variables of the distributed speed PID for ``n`` units."""
    return (
        Var("kp", "parameter", _D.kp, "1/s", "m/s2 of demand per m/s of speed error", min=0.0),
        Var("ki", "parameter", _D.ki, "1/s2", "m/s2 of demand per m of integrated error",
            min=0.0),
        Var("kd", "parameter", _D.kd, "1", "m/s2 of demand per m/s2 of measured acceleration",
            min=0.0),
        Var("derivative_filter", "parameter", _D.derivative_filter, "s",
            "time constant of the derivative low-pass (0: none)", min=0.0),
        Var("accel_min", "parameter", _D.accel_min, "m/s2", "most negative demand"),
        Var("accel_max", "parameter", _D.accel_max, "m/s2", "largest demand"),
        Var("rate_limit", "parameter", _D.rate_limit, "m/s3",
            "largest change of the demand per second (0: unlimited)", min=0.0),
        Var("feedforward", "parameter", _D.feedforward, description=
            "add the reference acceleration to the demand"),
        Var("sample_time", "parameter", _D.sample_time, "s", "sample time T", min=1e-6),
        Var("mass", "parameter", 479.5e3, "kg", "effective train mass M (1 + gamma)", min=1.0),
        Var("hold_accel", "parameter", _DD.hold_accel, "m/s2",
            "brake demand holding the train at the final stop", max=0.0),
        Var("stop_speed", "parameter", _DD.stop_speed, "m/s",
            "below this speed with a zero reference the holding brake is applied", min=0.0),
        Var("reference", "parameter", "jinan_xuzhou_east_reference", description=
            "bundled reference profile name or path of a CSV/TOML profile"),
        Var("v", "input", 0.0, "m/s", "measured train speed"),
        Var("s", "input", 0.0, "m", "measured head position"),
        *[Var(f"traction_limit[{i}]", "input", 0.0, "N",
              f"traction force unit {i} can give now") for i in range(1, n + 1)],
        *[Var(f"brake_limit[{i}]", "input", 0.0, "N", f"brake force unit {i} can give now")
          for i in range(1, n + 1)],
        *[Var(f"force[{i}]", "output", 0.0, "N", f"force command of unit {i}")
          for i in range(1, n + 1)],
        Var("force_demand", "output", 0.0, "N", "total force demand M a_dem"),
        Var("accel_demand", "output", 0.0, "m/s2", "acceleration demand a_dem"),
        Var("v_ref", "output", 0.0, "m/s", "reference speed"),
        Var("a_ref", "output", 0.0, "m/s2", "reference acceleration"),
        Var("speed_error", "output", 0.0, "m/s", "v - v_ref"),
        *CONTROLLER_TIMING_VARS,
    )


class _SpeedPidSlave(SampledControllerSlave):
    """Common part of the EMU speed-PID FMUs (not an FMU itself: no variables)."""

    units: ClassVar[int] = 0
    default_experiment_stop_time = 100.0
    default_experiment_step = 0.2

    def make_core(self) -> DistributedSpeedPid:
        val = self.values
        pid = SpeedPidParams(**{k: val[k] for k in SpeedPidParams.__dataclass_fields__})
        params = DistributedSpeedPidParams(pid=pid, units=self.units, mass=val["mass"],
                                           hold_accel=val["hold_accel"],
                                           stop_speed=val["stop_speed"])
        profile = load_reference(val["reference"],
                                 routes_dir=self.resource_path("plants", "routes"))
        return DistributedSpeedPid(params, profile)


class EmuSpeedPid3Fmu(_SpeedPidSlave):
    """Speed-tracking PID with per-unit force distribution for a 3-unit EMU (seeds 001, 004)."""

    units = 3
    variables = speed_pid_variables(3)


class EmuSpeedPid8Fmu(_SpeedPidSlave):
    """Speed-tracking PID with per-unit force distribution for an 8-car EMU (seed 004)."""

    units = 8
    variables = speed_pid_variables(8)
