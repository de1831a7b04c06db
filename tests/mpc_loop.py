"""Direct closed loop of a seed 000 plant core and a predictive controller core (no FMI).

At each controller event the core computes from the plant outputs; the plant then advances by
one sample with the held command. Used by the MPC tests for fast, master-independent checks.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from controllers.mpc.stop_mpc import StopMpcParams
from cosim.fmu.state import to_ticks
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
    T = params.sample_time
    steps = int(round(stop_time / T))
    out = LoopResult()
    next_event, u_prev, u = 0, None, 0.0
    for k in range(steps):
        y = plant.outputs()
        if k == next_event:
            res, hold = core.compute(k * T, {"v": y["v"], "s": y["s"], "a_c": y["a_c"]})
            u = res["brake_command"]
            next_event = k + max(1, hold)
            out.executions += 1
        if u_prev is not None and u != u_prev:
            out.switches += 1
        u_prev = u
        out.t.append(k * T)
        out.v.append(y["v"])
        out.s.append(y["s"])
        out.u.append(u)
        plant.advance(to_ticks(k * T), to_ticks(T), {"brake_command": u})
    y = plant.outputs()
    out.t.append(steps * T)
    out.v.append(y["v"])
    out.s.append(y["s"])
    out.u.append(u)
    return out
