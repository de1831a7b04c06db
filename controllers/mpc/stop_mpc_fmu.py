"""FMUs of the seed 000 predictive stopping controllers (:mod:`controllers.mpc.stop_mpc`)."""

from __future__ import annotations

from controllers.mpc.stop_mpc import IdealStopMpc
from cosim.fmu.slave import SampledControllerSlave


class StopMpcFmu(SampledControllerSlave):
    """Ideal MPC for accurate stopping: resistance known and fed forward (seed 000, sec. 2.1)."""

    core_class = IdealStopMpc
    default_experiment_stop_time = 60.0
    default_experiment_step = 0.2
