"""The core-level closed loop (:func:`cosim.fmu.closed_loop.closed_loop`): the master's timing
contract on toy cores, and the master's numbers on the seed 000 PID loop."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from controllers.pid.stop_pid import StopPid, StopPidParams
from cosim.fmu.closed_loop import closed_loop
from plants.brake_delay import BrakeDelayParams, BrakeDelayTrain
from plants.route import load_route


class Integrator:
    """x' = u: the plant's output is its state; it logs every advance (t, h, u)."""

    def __init__(self) -> None:
        self.x, self.steps = 0.0, []

    def outputs(self) -> dict[str, float]:
        return {"x": self.x, "hidden": -1.0}

    def advance(self, t_ticks: int, h_ticks: int, inputs: dict[str, Any]) -> None:
        self.steps.append((t_ticks, h_ticks, dict(inputs)))
        self.x += inputs["u"] * h_ticks / 1e9


class EveryThird:
    """u = 1 + x at its events, which come 3 samples apart (a self-triggered controller)."""

    def __init__(self) -> None:
        self.seen: list[tuple[float, dict[str, Any]]] = []

    def compute(self, t: float, inputs: dict[str, Any]) -> tuple[dict[str, float], int]:
        self.seen.append((t, dict(inputs)))
        return {"u": 1.0 + inputs["x"], "note": t}, 3


def test_events_holds_and_feedthrough_follow_the_timing_contract() -> None:
    plant, ctl = Integrator(), EveryThird()
    loop = closed_loop(plant, ctl, stop_time=1.0, sample_time=0.1, inputs=("x",),
                       commands=("u",))
    assert loop.time.tolist() == [k / 10 for k in range(11)]  # ticks / 1e9: no drift
    assert loop.event.nonzero()[0].tolist() == [0, 3, 6, 9]  # hold = 3 samples
    assert loop.executions == 4
    # the controller reads the plant at its event time, and only the inputs named
    assert [t for t, _ in ctl.seen] == [0.0, 0.3, 0.6, 0.9]
    assert all(set(seen) == {"x"} for _, seen in ctl.seen)
    assert [seen["x"] for _, seen in ctl.seen] == loop.plant["x"][[0, 3, 6, 9]].tolist()
    # the command acts from its event on, held in between; the plant steps one sample at a time
    assert [(t, h) for t, h, _ in plant.steps] == [(k * 10**8, 10**8) for k in range(10)]
    assert all(u == {"u": loop.controller["u"][k]} for k, (_, _, u) in enumerate(plant.steps))
    assert loop.controller["u"][:3].tolist() == [1.0] * 3
    # x integrates the held command exactly: 0.3 s at u = 1, then u = 1.3 ...
    assert loop.plant["x"][3] == pytest.approx(0.3, rel=1e-15)
    assert loop.controller["u"][3] == pytest.approx(1.3, rel=1e-15)
    # the last point: the plant at stop_time, the held outputs, no event
    assert not loop.event[-1] and loop.controller["u"][-1] == loop.controller["u"][9]


def test_a_non_positive_sample_time_is_refused() -> None:
    with pytest.raises(ValueError, match="sample_time = 0"):
        closed_loop(Integrator(), EveryThird(), 1.0, 0)


def test_the_loop_gives_the_masters_numbers_on_the_seed000_pid(built_fmus) -> None:
    """The cores of seed000_stop_pid in closed loop and the master running their FMUs: the
    same laws on the same grid, so the same numbers up to rounding (the FMU may take the
    compiled-kernel path where the core here takes numpy's; a few ulps per step over 300
    steps, far below 1e-9 of each signal's scale)."""
    from cosim.run.simulate import run_scenario

    route = load_route("seed000_stop")
    params = StopPidParams()
    loop = closed_loop(BrakeDelayTrain(BrakeDelayParams(), route, v0=20.0),
                       StopPid(params, route), 60.0, params.sample_time, inputs=("v", "s"),
                       commands=("brake_command",))
    frame = run_scenario("seed000_stop_pid", plot=False).frame
    assert np.array_equal(frame["time"].to_numpy(), loop.time)
    for column, ours, scale in (("plant.s", loop.plant["s"], 400.0),
                                ("plant.v", loop.plant["v"], 20.0),
                                ("controller.brake_command", loop.controller["brake_command"],
                                 100.0)):
        assert frame[column].to_numpy() == pytest.approx(ours, rel=0, abs=1e-9 * scale), column
