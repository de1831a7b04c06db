"""FMU wrapper of :class:`controllers.pid.stop_pid.StopPid` (seed 000 baseline)."""

from __future__ import annotations

from controllers.pid.stop_pid import StopPid, StopPidParams
from cosim.fmu.slave import CONTROLLER_TIMING_VARS, SampledControllerSlave, Var

_D = StopPidParams()


class StopPidFmu(SampledControllerSlave):
    """PID brake controller tracking the stopping curve v_ref(s) = sqrt(2 a0 (s_stop - s))."""

    default_experiment_stop_time = 60.0
    default_experiment_step = 0.2
    variables = (
        Var("kp", "parameter", _D.kp, "%.s/m", "proportional gain on v - v_ref"),
        Var("ki", "parameter", _D.ki, "%/m", "integral gain"),
        Var("kd", "parameter", _D.kd, "%/(m/s2)", "derivative gain"),
        Var("ref_decel", "parameter", _D.ref_decel, "m/s2", "a0: reference deceleration",
            min=1e-6),
        Var("stop_point", "parameter", _D.stop_point, "m", "stop position s_stop"),
        Var("brake_gain", "parameter", _D.brake_gain, "m/s2/%",
            "c: deceleration per % of command, for the feedforward a0 / c", min=1e-9),
        Var("feedforward", "parameter", _D.feedforward, description=
            "add the reference-deceleration feedforward a0 / c"),
        Var("u_min", "parameter", _D.u_min, "%", "lowest brake command"),
        Var("u_max", "parameter", _D.u_max, "%", "highest brake command"),
        Var("sample_time", "parameter", _D.sample_time, "s", "sample time T", min=1e-6),
        Var("v", "input", 0.0, "m/s", "measured speed"),
        Var("s", "input", 0.0, "m", "measured position"),
        Var("brake_command", "output", 0.0, "%", "brake command u"),
        Var("v_ref", "output", 0.0, "m/s", "reference speed at the measured position"),
        Var("speed_error", "output", 0.0, "m/s", "v - v_ref"),
        *CONTROLLER_TIMING_VARS,
    )

    def make_core(self) -> StopPid:
        names = StopPidParams.__dataclass_fields__
        return StopPid(StopPidParams(**{k: self.values[k] for k in names}))
