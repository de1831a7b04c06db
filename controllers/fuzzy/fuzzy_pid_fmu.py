"""FMU of :class:`controllers.fuzzy.fuzzy_pid.FreightFuzzyPid` (seed 002 baseline)."""

from __future__ import annotations

from controllers.fuzzy.fuzzy_pid import FreightFuzzyPid
from cosim.fmu.slave import SampledControllerSlave


class FreightFpidFmu(SampledControllerSlave):
    """Fuzzy PID speed tracking of the freight train with the shared blending (seed 002)."""

    core_class = FreightFuzzyPid
    default_experiment_stop_time = 100.0
    default_experiment_step = 0.2
