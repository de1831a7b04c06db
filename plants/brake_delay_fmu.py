"""FMU of :class:`plants.brake_delay.BrakeDelayTrain` (seed 000 plant): its variables are the
core's declarations."""

from __future__ import annotations

from cosim.fmu.slave import PlantSlave
from plants.brake_delay import BrakeDelayTrain


class BrakeDelayTrainFmu(PlantSlave):
    """High-speed train, brake command through first-order lag plus dead time (seed 000)."""

    core_class = BrakeDelayTrain
    default_experiment_stop_time = 60.0
    default_experiment_step = 0.2
