"""A plant core and a controller core in closed loop, without FMUs or a master, on the timing
contract the master keeps (``docs/architecture.md``):

* time is integer nanoseconds (:func:`cosim.fmu.state.to_ticks`); the loop communicates every
  ``sample_time`` (the controller's grid, anchored at t = 0), so the communication points are
  ``t_k = k * sample_time`` for ``k = 0 .. n``, ``n = round(stop_time / sample_time)``;
* the controller has an event at t = 0 and then ``max(1, hold)`` samples after each event,
  ``hold`` being what its ``compute`` returned (1 for a periodic controller, more for a
  self-triggered one), as the FMU wrapper computes ``next_event_time``;
* at an event the controller computes from the plant's outputs at ``t_k`` (direct feedthrough),
  and its outputs act on the plant from ``t_k`` on, held until its next event;
* the plant advances from ``t_k`` to ``t_{k+1}`` with the held command (``advance(t_ticks,
  h_ticks, inputs)``, the plant's own sub-steps inside).

A plant core provides ``outputs() -> dict`` and ``advance(t_ticks, h_ticks, inputs)``, a
controller core ``compute(t_s, inputs) -> (outputs, hold)``: the cores of ``plants/`` and
``controllers/``, which their FMU wrappers (:mod:`cosim.fmu.slave`) wrap.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from cosim.fmu.state import to_seconds, to_ticks


class PlantCore(Protocol):
    """What the loop asks of a plant core."""

    def outputs(self) -> Mapping[str, Any]: ...

    def advance(self, t_ticks: int, h_ticks: int, inputs: Mapping[str, Any]) -> None: ...


class ControllerCore(Protocol):
    """What the loop asks of a controller core: outputs and the samples until its next event."""

    def compute(self, t: float, inputs: Mapping[str, Any]) -> tuple[Mapping[str, Any], int]: ...


@dataclass(frozen=True)
class LoopResult:
    """The signals of a closed loop at its communication points ``time`` (s, ``t_k``)."""

    time: np.ndarray  # s, k * sample_time for k = 0 .. n
    plant: dict[str, np.ndarray]  # each plant output at t_k (before the step from t_k)
    controller: dict[str, np.ndarray]  # each controller output held at t_k (its last event's)
    event: np.ndarray  # bool per t_k: the controller computed at t_k

    @property
    def executions(self) -> int:
        """The controller's events."""
        return int(self.event.sum())


def closed_loop(plant: PlantCore, controller: ControllerCore, stop_time: float,
                sample_time: float, inputs: Sequence[str] | None = None,
                commands: Sequence[str] | None = None) -> LoopResult:
    """Run ``controller`` on ``plant`` from t = 0 to ``stop_time`` (s) on the controller's grid
    of ``sample_time`` (s), as the master runs their FMUs (module docstring). ``inputs``: the
    plant outputs the controller reads (all without); ``commands``: the controller outputs the
    plant reads (all without). The last point is ``stop_time``: the plant there, the
    controller's outputs held (no event at the end, nothing follows it)."""
    step = to_ticks(sample_time)
    if step <= 0:
        raise ValueError(f"sample_time = {sample_time!r} s: must be > 0")
    n = round(to_ticks(stop_time) / step)
    measured: list[Mapping[str, Any]] = []
    held: list[Mapping[str, Any]] = []
    event = np.zeros(n + 1, dtype=bool)
    out: Mapping[str, Any] = {}
    next_event = 0
    for k in range(n + 1):
        y = plant.outputs()
        if k == next_event and k < n:
            read = y if inputs is None else {name: y[name] for name in inputs}
            out, hold = controller.compute(to_seconds(k * step), read)
            next_event = k + max(1, int(hold))
            event[k] = True
        measured.append(dict(y))
        held.append(dict(out))
        if k < n:
            plant.advance(k * step, step, out if commands is None
                          else {name: out[name] for name in commands})
    return LoopResult(
        time=np.array([to_seconds(k * step) for k in range(n + 1)]),
        plant={name: np.array([y[name] for y in measured]) for name in measured[0]},
        controller={name: np.array([o.get(name, np.nan) for o in held]) for name in held[0]},
        event=event)
