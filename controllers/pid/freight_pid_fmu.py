"""FMU of :class:`controllers.pid.freight_pid.FreightPid` (seed 002 baseline)."""

from __future__ import annotations

from controllers.pid.freight_pid import FreightPid
from cosim.fmu.slave import SampledControllerSlave


class FreightPidFmu(SampledControllerSlave):
    """Freight speed PID with traction / electric brake / air brake blending (seed 002)."""

    core_class = FreightPid
    default_experiment_stop_time = 100.0
    default_experiment_step = 0.2
