"""What a run can end with besides its stop time: a failed FMI call, or an FMU ending it."""

from __future__ import annotations

from typing import Any

from cosim.fmu.state import to_seconds


class SimulationError(RuntimeError):
    """An FMU call failed during a run; the message names the FMU, the call and the time."""


class FmuCallError(SimulationError):
    """An FMI call other than doStep failed; ``status`` is the FMI status (3 error, 4 fatal)."""

    def __init__(self, message: str, status: int | None = None) -> None:
        super().__init__(message)
        self.status = status


class FmuTerminated(Exception):  # noqa: N818 - a normal end of the run, not an error
    """An FMU ended the simulation: FMI 2 doStep returned fmi2Discard with fmi2Terminated true
    (FMI 2.0.4 sec. 4.2.2), or FMI 3 fmi3DoStep / fmi3UpdateDiscreteStates returned
    ``terminateSimulation`` (FMI 3.0 sec. 4.2.1, 2.3.5); ``ticks`` is its last successful
    time."""

    def __init__(self, unit: Any, ticks: int) -> None:
        super().__init__(f"{unit.name} terminated the simulation at t={to_seconds(ticks)} s")
        self.unit = unit
        self.ticks = ticks
