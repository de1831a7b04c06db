"""FMU of the seed-003 LMI robust MPC tracker (:mod:`controllers.robust.rmpc`); interface
:mod:`controllers.eco.tracking` (the GPC baseline's)."""

from __future__ import annotations

from controllers.robust.rmpc import Crh3LmiMpc
from cosim.fmu.slave import SampledControllerSlave


class Crh3LmiMpcFmu(SampledControllerSlave):
    """Multi-model LMI robust MPC (Kothare; not seed 000's tube RMPC) tracking the seed-003
    profiles of a CRH3."""

    core_class = Crh3LmiMpc
    default_experiment_stop_time = 2200.0
    default_experiment_step = 1.0
