"""FMU of the seed-003 LMI robust MPC tracker (:mod:`controllers.robust.rmpc`); interface
:mod:`controllers.eco.tracking` (the GPC baseline's)."""

from __future__ import annotations

from controllers.robust.rmpc import Crh3Rmpc
from cosim.fmu.slave import SampledControllerSlave


class Crh3RmpcFmu(SampledControllerSlave):
    """Multi-model LMI robust MPC tracking the conventional / eco profile of a CRH3 (seed 003)."""

    core_class = Crh3Rmpc
    default_experiment_stop_time = 2200.0
    default_experiment_step = 1.0
