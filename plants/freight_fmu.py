"""FMU of :class:`plants.freight.FreightTrain` (seed 002: HXD1 + 108 loaded C80)."""

from __future__ import annotations

from cosim.fmu.slave import PlantSlave
from plants.freight import FreightTrain


class FreightTrainFmu(PlantSlave):
    """Heavy freight train HXD1 + 108 C80: couplers, traction lag, air-brake wave (seed 002)."""

    core_class = FreightTrain
    default_experiment_stop_time = 60.0
    default_experiment_step = 0.2
