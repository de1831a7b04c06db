"""Direct closed loop of a seed 000 plant core and a predictive controller core (no FMI).

The loop is :func:`cosim.fmu.closed_loop.closed_loop` (the master's timing); this keeps the
figures the MPC tests check. Used for fast, master-independent checks.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from controllers.mpc.stop_mpc import StopMpcParams
from cosim.fmu.closed_loop import closed_loop
from plants.brake_delay import BrakeDelayParams, BrakeDelayTrain
from plants.route import load_route


@dataclass
class LoopResult:
    t: list[float] = field(default_factory=list)
    v: list[float] = field(default_factory=list)
    s: list[float] = field(default_factory=list)
    u: list[float] = field(default_factory=list)
    executions: int = 0
    switches: int = 0

    @property
    def stop_error(self) -> float:
        return self.s[-1] - 400.0


def run_loop(core, params: StopMpcParams, stop_time: float = 60.0, v0: float = 20.0,
             plant_params: BrakeDelayParams | None = None,
             route: str = "seed000_stop") -> LoopResult:
    plant = BrakeDelayTrain(plant_params or BrakeDelayParams(), load_route(route), v0=v0)
    loop = closed_loop(plant, core, stop_time, params.sample_time, inputs=("v", "s", "a_c"),
                       commands=("brake_command",))
    u = loop.controller["brake_command"]
    return LoopResult(t=list(loop.time), v=list(loop.plant["v"]), s=list(loop.plant["s"]),
                      u=list(u), executions=loop.executions,
                      switches=int(np.count_nonzero(u[1:] != u[:-1])))
