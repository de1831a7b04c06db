"""One FMU instance behind one interface, whatever its FMI version (libcosim's "slave").

:class:`Unit` holds what every version shares: the variables by name (each with the get/set
function family it goes through), values by name, the communication-step loop with the
instance's ``max_step``, the schedule of a sampled or self-triggered FMU, and the FMU's log.
A subclass per standard (:class:`cosim.run.master.fmi2.Fmi2Unit`,
:class:`cosim.run.master.fmi3.Fmi3Unit`) implements the calls: instantiate, initialise, one
doStep, events, state save/restore, terminate, free. The algorithms and the recorder only
use this interface.
"""

from __future__ import annotations

import math
import time
from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from cosim.fmu.state import to_seconds, to_ticks
from cosim.run.dependencies import output_dependencies
from cosim.run.fmi_batch import Batch
from cosim.run.fmi_types import FUNCTIONS, to_fmi
from cosim.run.master.errors import FmuCallError, FmuTerminated, SimulationError

# Discard policy: a refused step is retried from the FMU's last successful time in pieces of
# half the refused size, down to 1/2**MAX_HALVINGS of the communication step.
MAX_HALVINGS = 10


@dataclass
class Variable:
    vr: int
    type: str
    causality: str
    items: dict[str, int] = field(default_factory=dict)  # Enumeration item name -> value
    family: str = ""  # the get/set function family (``Real``, ``Int64`` ...)
    # an element of an FMI 3 array variable: (its size, this element's 0-based index)
    element: tuple[int, int] | None = None

    def __post_init__(self) -> None:
        if not self.family:
            self.family = FUNCTIONS.get(self.type, self.type)


class Unit(ABC):
    """One FMU instance: values by name, doStep accounting, scheduling information."""

    fmi_version = ""
    # family -> ctypes type of the C get/set functions called directly (fmi_batch.Batch)
    C_TYPES: dict[str, Any] = {}
    C_PREFIX = ""  # "fmi2" / "fmi3"
    C_COUNTS = False  # the C get/set functions take the number of values (FMI 3)

    def __init__(self, name: str, path: Path, unzipdir: str, md: Any) -> None:
        self.name = name
        self.path = path
        self.md = md
        self.vars: dict[str, Variable] = self.variables(md)
        self.deps = output_dependencies(md)  # absent dependencies attribute: all inputs
        self.feedthrough = any(self.deps.values())
        # a Scheduled Execution FMU (no co-simulation interface) takes any time between
        # activations
        self.variable_step = (md.coSimulation is None
                              or bool(md.coSimulation.canHandleVariableCommunicationStepSize))
        experiment = md.defaultExperiment
        step = getattr(experiment, "stepSize", None) if experiment is not None else None
        # the FMU's own communication step (DefaultExperiment stepSize), ticks; None: not given
        self.default_step_ticks: int | None = (to_ticks(float(step)) if step is not None
                                               and float(step) > 0 else None)
        self.has_next_event_output = "next_event_time" in self.vars
        self.reset_run_state()

    def reset_run_state(self) -> None:
        """The run-dependent state of this side of the instance, as before its first run:
        time, counters, schedule and log."""
        self.time_ticks = 0
        self.do_steps = 0
        self.wall_time = 0.0
        self.loop_wall_time = 0.0  # s, the communication points alone (benchmarks)
        self.loop_cpu_time = 0.0  # s, CPU time of this process over the same
        self.sample_ticks: int | None = None
        self.max_step_ticks: int | None = None
        self.next_event_ticks: int | None = None
        self.messages: list[str] = []

    @staticmethod
    def scenario_view(md: Any) -> Any:
        """``md`` as the scenario checks see the variables (FMI 3: array elements, no
        clocks)."""
        return md

    # -- what each FMI version implements ------------------------------------------------------
    @abstractmethod
    def variables(self, md: Any) -> dict[str, Variable]:
        """The variables of ``md`` by name (array elements as ``name[i]``, 1-based)."""

    @abstractmethod
    def instantiate(self, event_mode: bool = False) -> None:
        """Instantiate; ``event_mode``: the algorithm handles the FMU's events (FMI 3)."""

    @abstractmethod
    def enter_initialization(self, start: float, stop: float) -> None:
        """Parameters and start values are set: enter Initialization Mode."""

    @abstractmethod
    def exit_initialization(self) -> None: ...

    @abstractmethod
    def _do_step(self, t: int, h: int) -> int:
        """One communication step from ``t`` over ``h`` (ticks): the time reached (``t + h``,
        or earlier on an early return)."""

    @abstractmethod
    def read(self, family: str, vrs: list[int]) -> list[Any]:
        """One get of ``vrs`` of function family ``family``."""

    @abstractmethod
    def write(self, family: str, vrs: list[int], values: list[Any]) -> None:
        """One set of ``vrs`` (values as the getters return them or as :func:`to_fmi`
        converts them)."""

    @abstractmethod
    def get_state(self) -> Any: ...

    @abstractmethod
    def set_state(self, state: Any) -> None: ...

    @abstractmethod
    def terminate(self) -> None: ...

    reusable = False  # reset() is implemented: the instance serves another run

    def reset(self) -> None:
        """The instance back to its state right after :meth:`instantiate` (every variable at
        its start value) and :meth:`reset_run_state`, for another run without a new instance."""
        raise NotImplementedError(f"{type(self).__name__} cannot be reset")

    @abstractmethod
    def free(self) -> None: ...

    @abstractmethod
    def raw_slave(self) -> Any:
        """The fmpy object with ``dll`` and ``component`` (fmi_batch's direct calls)."""

    # -- events (FMI 3 Event Mode, clocks); an FMU without them has none ---------------------
    def event_time(self) -> int | None:
        """The next time (ticks) this FMU needs a communication point and an event there."""
        return None

    def event_pending(self, ticks: int) -> bool:
        """Does this FMU have an event to handle at ``ticks`` (this communication point)?"""
        return False

    def begin_event(self, ticks: int) -> None:
        """Enter Event Mode at ``ticks`` (before its inputs are set at this point)."""
        return None

    def complete_event(self, ticks: int) -> None:
        """Handle the event at ``ticks`` (clock ticks, discrete states) and go back to
        stepping; the FMU's outputs are its post-event values afterwards."""
        return None

    may_return_early = False  # doStep may end before the requested time
    has_events = False  # events come from event_time() / event_pending() (FMI 3 Event Mode)

    # -- shared --------------------------------------------------------------------------------
    def last_messages(self, n: int = 3) -> str:
        """The FMU's last log messages, for error reports."""
        return " | ".join(m.strip() for m in self.messages[-n:])

    def fmu_reason(self, err: BaseException) -> str:
        """Why a call failed, in the FMU's words when it said why (our FMUs log the Python
        exception's message as "<instance>: <call> rejected: <message>"), else fmpy's error
        and the FMU's last log messages."""
        for message in reversed(self.messages[-5:]):
            if " rejected: " in message:
                return message.split(" rejected: ", 1)[1].strip()
        said = self.last_messages()
        return f"{err}" + (f"; FMU says: {said}" if said else "")

    def call_failed(self, call: str, status: int) -> None:
        """Raise the :class:`FmuCallError` of a failed FMI call (``call`` as fmpy names it)."""
        from fmpy.fmi1 import FMICallException

        err = FMICallException(function=f"{self.C_PREFIX}{call[0].upper()}{call[1:]}",
                               status=status)
        raise FmuCallError(self.call_error_text(call, err), status) from err

    def call_error_text(self, call: str, err: BaseException) -> str:
        """The message of a failed FMI call: instance, call, time and the FMU's reason."""
        return (f"{self.name}: {call} at t = {to_seconds(self.time_ticks):g} s failed: "
                f"{self.fmu_reason(err)}")

    def batch(self, family: str, vrs: list[int], setter: bool, buffer: Any = None) -> Batch:
        """A reusable get/set of ``vrs`` (after instantiation)."""
        return Batch(self, family, vrs, setter, self.call_failed, buffer)

    def batches(self, names: list[str]) -> list[tuple[str, list[int], list[int]]]:
        """``names`` grouped by function family: (family, value references, positions in
        ``names``), one FMI call each, families in first-appearance order."""
        groups: dict[str, tuple[str, list[int], list[int]]] = {}
        for i, name in enumerate(names):
            var = self.vars[name]
            group = groups.setdefault(var.family, (var.family, [], []))
            group[1].append(var.vr)
            group[2].append(i)
        return list(groups.values())

    def get(self, names: list[str]) -> list[Any]:
        """Values of ``names``: one FMI call per function family."""
        out: list[Any] = [None] * len(names)
        for family, vrs, where in self.batches(names):
            for i, value in zip(where, self.read(family, vrs)):
                out[i] = value
        return out

    def set(self, name: str, value: Any) -> None:
        var = self.vars[name]
        self.write(var.family, [var.vr], [to_fmi(var.type, value, var.items)])

    def step_to(self, ticks: int, first_status: int | None = None) -> int:
        """doStep from this FMU's own time to ``ticks``, in steps of at most the instance's
        ``max_step`` (inputs held over them) when a master's step is longer: the time
        reached (earlier than ``ticks`` when the FMU returned early). ``first_status``: the
        first doStep was made already (by the C loop) and returned this status (FMI 2)."""
        t0 = time.perf_counter()
        try:
            while self.time_ticks < ticks:
                h = ticks - self.time_ticks
                if self.max_step_ticks:
                    h = min(h, self.max_step_ticks)
                try:
                    if first_status is None:
                        reached = self._do_step(self.time_ticks, h)
                    else:
                        reached = self._do_step(self.time_ticks, h,  # type: ignore[call-arg]
                                                first_status=first_status)
                        first_status = None
                except (FmuTerminated, SimulationError):
                    raise
                except Exception as err:  # fmpy raises FMICallException with the status
                    raise SimulationError(f"{self.name}: doStep at t = "
                                          f"{to_seconds(self.time_ticks):g} s, h = "
                                          f"{to_seconds(h):g} s failed: "
                                          f"{self.fmu_reason(err)}") from err
                self.time_ticks = reached
                if self.returned_early:
                    break
        finally:
            self.wall_time += time.perf_counter() - t0
        return self.time_ticks

    returned_early = False  # the last doStep ended early (FMI 3 earlyReturn)

    def update_schedule(self, now: int, announced: float | None = None) -> None:
        """Next event after an event at ``now``: announced by the FMU (its
        ``next_event_time``, read now unless ``announced`` gives it) or periodic."""
        if self.has_next_event_output:
            value = announced if announced is not None else self.get(["next_event_time"])[0]
            nxt = to_ticks(value) if math.isfinite(value) else None
            if nxt is None or nxt <= now:  # an FMU fault: never clamped, which would hide it
                raise SimulationError(f"{self.name}: next_event_time = {value!r} s is not after "
                                      f"the current time {to_seconds(now)!r} s (an FMU "
                                      "announcing its next event must give a later time)")
            self.next_event_ticks = nxt
        elif self.sample_ticks is not None:
            self.next_event_ticks = now + self.sample_ticks

    @property
    def scheduled(self) -> bool:
        return self.has_next_event_output or self.sample_ticks is not None

