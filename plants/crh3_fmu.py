"""FMU of :class:`plants.crh3.Crh3Train` (seed 003 plant): its variables are the core's
declarations."""

from __future__ import annotations

from cosim.fmu.slave import PlantSlave
from plants.crh3 import Crh3Train


class Crh3TrainFmu(PlantSlave):
    """CRH3 single mass with traction/brake lag, envelope and energy account (seed 003)."""

    core_class = Crh3Train
    default_experiment_stop_time = 2200.0
    default_experiment_step = 1.0
