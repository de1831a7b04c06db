"""FMU of the seed-003 GPC tracker (:mod:`controllers.eco.gpc`); interface
:mod:`controllers.eco.tracking`."""

from __future__ import annotations

from controllers.eco.gpc import Crh3Gpc
from cosim.fmu.slave import SampledControllerSlave


class Crh3GpcFmu(SampledControllerSlave):
    """GPC tracking of the conventional / eco profile of a CRH3 (seed 003 baseline)."""

    core_class = Crh3Gpc
    default_experiment_stop_time = 2200.0
    default_experiment_step = 1.0
