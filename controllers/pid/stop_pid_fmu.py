"""FMU of :class:`controllers.pid.stop_pid.StopPid` (seed 000 baseline)."""

from __future__ import annotations

from controllers.pid.stop_pid import StopPid
from cosim.fmu.slave import SampledControllerSlave


class StopPidFmu(SampledControllerSlave):
    """PID brake controller tracking the stopping curve v_ref(s) = sqrt(2 a0 (s_stop - s))."""

    core_class = StopPid
    default_experiment_stop_time = 60.0
    default_experiment_step = 0.2
