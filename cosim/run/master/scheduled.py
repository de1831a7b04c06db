"""The FMI 3.0 Scheduled Execution unit on fmpy's ``FMU3ScheduledExecution`` (FMI 3.0 chap. 5).

A Scheduled Execution FMU has no doStep: after Initialization Mode it is in Clock Activation
Mode, and the master runs each of its model partitions with
``fmi3ActivateModelPartition(clockReference, activationTime)`` when the partition's input clock
ticks (sec. 5.2.1):

* periodic clocks (``constant``, ``fixed``, ``tunable``) tick at start + shift + k interval,
  attributes and FMU queries as for co-simulation (:mod:`cosim.run.master.fmi3`);
* a ``countdown`` clock ticks when the FMU says so: first where its interval asked in
  Initialization Mode puts it (sec. 2.2.8.2, countdown Clock: t_0 = t_start + interval, when
  the qualifier is ``fmi3IntervalChanged``; none when ``fmi3IntervalNotYetKnown``), then
  after the FMU calls the clock-update callback (sec. 5.2.1) from inside a partition, when
  the master asks its interval (fmi3GetIntervalDecimal, qualifier ``fmi3IntervalChanged``):
  it ticks that long after the activation that set it; interval 0 is a tick at the same
  time, after the partition that set it;
* a ``changing`` clock ticks first where its interval asked in Initialization Mode puts it,
  then that long after each of its activations that the master asks its interval right after
  (sec. 2.2.8.2: fmi3GetInterval in Clock Activation Mode if and only if the Clock ticked);
  interval 0 as for a countdown clock;
* a ``triggered`` clock ticks where an output clock wired to it in the scenario's
  [connections] ticks (the master asks every output clock with fmi3GetClock after each
  clock-update callback).

Every input clock declares a ``priority`` (sec. 2.4.4: required in Scheduled Execution;
lower value = higher priority). The master runs partitions one at a time (no preemption):
the partitions due at one time are activated in priority order (equal priorities: by value
reference), and a partition made due at that time by another (countdown 0, a trigger) joins
the queue in its priority. Inputs are set before and outputs read after the time's
activations, at the master's communication points (integer nanoseconds; an activation time
that is not a whole nanosecond is passed as the FMU's own double).
"""

from __future__ import annotations

import os
from typing import Any

from fmpy.fmi3 import (
    FMU3ScheduledExecution,
    fmi3ClockUpdateCallback,
    fmi3InstanceEnvironment,
    fmi3LockPreemptionCallback,
    fmi3LogMessageCallback,
    fmi3UnlockPreemptionCallback,
)

from cosim.run.master.errors import SimulationError
from cosim.run.master.fmi3 import Fmi3Unit


class Fmi3ScheduledUnit(Fmi3Unit):
    """An FMI 3.0 Scheduled Execution FMU instance."""

    UNSCHEDULED_CLOCKS = ("countdown", "changing", "triggered")
    FMPY_CLASS = FMU3ScheduledExecution
    INTERFACE = "scheduledExecution"

    def __init__(self, name: str, path: Any, unzipdir: str, md: Any) -> None:
        super().__init__(name, path, unzipdir, md)
        self._priority = {}
        for clock in self.input_clocks:
            if clock.priority is None:
                raise SimulationError(
                    f"{path}: modelDescription.xml: input Clock {clock.name!r} has no priority "
                    "(FMI 3.0 sec. 2.4.4: every input clock of a Scheduled Execution FMU "
                    "declares one)")
            self._priority[clock.value_reference] = (clock.priority, clock.value_reference)
        clock_vars = set(self.clock_names)
        self.deps = {out: inputs - clock_vars for out, inputs in self.deps.items()
                     if out not in clock_vars}
        self.feedthrough = any(self.deps.values())
        self._triggered: set[int] = set()  # triggered input clocks due at this point
        self._updated = False  # the FMU called the clock-update callback
        # every output clock is asked in Clock Update Mode (sec. 5.2.2)
        self.watched_clocks = [c.value_reference for c in self.output_clocks]
        self.activations: list[tuple[str, float]] = []  # (input clock, activation time s)
        self._changing = {c.value_reference: c for c in self.input_clocks
                          if c.interval_variability == "changing"}

    @staticmethod
    def _has_event_mode(md: Any) -> bool:
        return True  # Clock Activation Mode takes Event Mode's place

    def reset(self) -> None:
        """fmi3Reset (as :meth:`Fmi3Unit.reset`), and the activations of the last run
        forgotten: no triggered clock due, no clock update, no activation recorded."""
        super().reset()
        self._triggered = set()
        self._updated = False
        self.activations = []

    def instantiate(self, event_mode: bool = False) -> None:
        if not event_mode:
            raise SimulationError(f"{self.name}: a Scheduled Execution FMU runs its model "
                                  "partitions when their clocks tick, which this algorithm "
                                  "does not handle: run with algorithm = \"event\"")
        self.event_mode = self.has_events = True
        raw = self.slave._slave

        def log(env: Any, status: int, category: Any, message: Any) -> None:
            self.messages.append(message.decode("utf-8", "replace") if message else "")

        def clock_update(env: Any) -> None:
            self._updated = True

        def no_preemption() -> None:  # partitions run one at a time: nothing to lock
            return None

        self._callbacks = (fmi3LogMessageCallback(log), fmi3ClockUpdateCallback(clock_update),
                           fmi3LockPreemptionCallback(no_preemption),
                           fmi3UnlockPreemptionCallback(no_preemption))
        resources = os.path.join(raw.unzipDirectory, "resources") + os.path.sep
        raw.component = raw.fmi3InstantiateScheduledExecution(
            self.name.encode("utf-8"), raw.guid.encode("utf-8"), resources.encode("utf-8"),
            False, True, fmi3InstanceEnvironment(), *self._callbacks)
        if not raw.component:
            raise SimulationError(f"{self.name}: fmi3InstantiateScheduledExecution failed: "
                                  f"{self.last_messages() or 'the FMU gave no reason'}")

    def exit_initialization(self) -> None:
        super().exit_initialization()  # now in Clock Activation Mode (sec. 5.2.1)
        self._in_event = False

    def _do_step(self, t: int, h: int) -> int:
        return t + h  # time passes between activations; the FMU has no doStep

    def trigger(self, vr: int) -> None:
        """The triggered input clock ``vr`` ticks at this communication point."""
        self._triggered.add(vr)

    def event_pending(self, ticks: int) -> bool:
        return bool(self._triggered) or ticks in self._clock_next.values()

    def begin_event(self, ticks: int) -> None:
        return None

    def complete_event(self, ticks: int) -> None:
        """Activate every partition due at ``ticks`` in priority order (those made due
        meanwhile included); the output clocks that ticked are in ``self.ticked``."""
        now = self._seconds(ticks)
        due = {vr for vr, nxt in self._clock_next.items() if nxt == ticks} | self._triggered
        self._triggered = set()
        self.ticked = []
        names = {c.value_reference: c.name for c in self.input_clocks}
        while due:
            vr = min(due, key=self._priority.__getitem__)
            due.discard(vr)
            self._updated = False
            self.slave.activateModelPartition(vr, now)
            self.activations.append((names[vr], now))
            if self._clock_next.get(vr) == ticks:
                self._advance([vr], ticks)
            if vr in self._changing:  # its next interval, asked where it ticked
                due.update(self._ask_intervals(now, ticks, [self._changing[vr]],
                                               zero_allowed=True))
            if self._updated:
                due.update(self._ask_intervals(now, ticks, self._countdown_and_tunable(),
                                               zero_allowed=True))
                self._read_output_clocks()
