"""FMU of :class:`controllers.smc.sliding_mode.FreightSlidingMode` (seed 002 baseline)."""

from __future__ import annotations

from controllers.smc.sliding_mode import FreightSlidingMode
from cosim.fmu.slave import SampledControllerSlave


class FreightSmcFmu(SampledControllerSlave):
    """Sliding-mode speed tracking of the freight train with the shared blending (seed 002)."""

    core_class = FreightSlidingMode
    default_experiment_stop_time = 100.0
    default_experiment_step = 0.2
