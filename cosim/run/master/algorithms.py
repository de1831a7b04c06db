"""Stepping policies over the units of a :class:`cosim.run.master.core.Master` (libcosim's
algorithms): which FMUs step when, and in which order values flow. They see only the
:class:`cosim.run.master.unit.Unit` interface, whatever the FMUs' FMI versions."""

from __future__ import annotations

import logging
from abc import ABC, abstractmethod
from typing import TYPE_CHECKING

from cosim.fmu.state import to_seconds
from cosim.run import exchange
from cosim.run.master import native_loop
from cosim.run.master.errors import SimulationError

LOG = logging.getLogger(__name__)

if TYPE_CHECKING:
    from cosim.run.master.core import Master
    from cosim.run.master.unit import Unit


class Algorithm(ABC):
    """A stepping policy over the units of a :class:`Master`."""

    name = ""
    event_mode = False  # the FMUs' events (FMI 3 Event Mode, clocks) are handled here

    def __init__(self, master: Master) -> None:
        self.m = master

    @abstractmethod
    def run(self) -> None: ...


class EventDriven(Algorithm):
    """Next communication point = earliest of every scheduled FMU's next event (announced as
    ``next_event_time``, periodic ``sample_time``, FMI 3 ``nextEventTime`` or clock tick), the
    output points, each FMU's max step and the stop time. Plants step at every point; a
    scheduled (sampled or self-triggered) FMU steps only to its own events. An FMU that
    cannot handle variable communication step sizes steps on its own fixed grid of
    ``max_step`` (else its DefaultExperiment ``stepSize``, else ``base_step``, else
    ``output_interval``). An FMU that returns early
    (FMI 3) steps first and ends the point where it returned: the others step only to there;
    an FMU with a triggered input clock driven by another FMU's output clock steps after the
    FMUs that may return early, so it is at its source's tick time.
    Where every FMU is an FMI 2 instance called through its C functions, the same points run
    in C with the same calls (:mod:`cosim.run.master.native_loop`).
    """

    name = "event"
    event_mode = True

    def fixed_grid(self) -> None:
        """Give each FMU with canHandleVariableCommunicationStepSize = false a fixed step."""
        m = self.m
        span = m.stop_ticks - m.start_ticks
        for u in m.units:
            if u.variable_step:
                continue
            where = f"{m.scenario.path}: [fmus.{u.name}]"
            if u.has_next_event_output or u.event_time() is not None:
                raise SimulationError(
                    f"{where}: {u.name} announces its events but cannot handle variable "
                    "communication step sizes (canHandleVariableCommunicationStepSize=false): "
                    "the event algorithm cannot step it to them; run it with algorithm = "
                    '"fixed" (or --algorithm fixed)')
            if u.sample_ticks is None:
                u.sample_ticks = u.max_step_ticks or u.default_step_ticks or m.base_step_ticks
            step = u.sample_ticks
            if u.max_step_ticks and u.max_step_ticks < step:
                raise SimulationError(
                    f"{where}: max_step = {to_seconds(u.max_step_ticks)} s is shorter than its "
                    f"sample_time = {to_seconds(step)} s and the FMU cannot handle variable "
                    "communication step sizes (canHandleVariableCommunicationStepSize=false)")
            u.max_step_ticks = None
            if span % step:
                raise SimulationError(
                    f"{where}: the FMU cannot handle variable communication step sizes "
                    "(canHandleVariableCommunicationStepSize=false), so the event algorithm "
                    f"steps it every {to_seconds(step)} s, which does not divide the run "
                    f"({to_seconds(m.start_ticks)} s to {to_seconds(m.stop_ticks)} s): give "
                    f"[fmus.{u.name}] a max_step that does, or run with algorithm = \"fixed\"")

    def run(self) -> None:
        m = self.m
        self.fixed_grid()
        why = native_loop.why_not(m)
        if why is None:
            native_loop.NativeLoop(m).run()
            return
        LOG.debug("%s: the event-driven loop runs in Python: %s", m.scenario.path, why)
        rec = m.recorder
        t = m.start_ticks
        units = m.units
        scheduled = [u for u in units if u.scheduled]
        limited = [u for u in units if not u.scheduled and u.max_step_ticks]
        eventful = [u for u in units if u.has_events]
        early = [u for u in units if u.may_return_early and not u.scheduled]
        # an FMU whose triggered input clock another FMU's output clock drives steps after the
        # others: it reaches no further than where a source returned early, its tick time
        # (FMI 3.0 sec. 2.2.8.2)
        early.sort(key=lambda u: bool(getattr(u, "time_sources", ())))
        late = [u for u in units if u not in early]
        due = set(units)
        while True:
            m.propagate(due, t)
            recording = m.output_point(t)
            if recording:  # first: a bad announced event below still keeps this point
                rec.sample(t)
                rec.commit()
                m.advance_output(t)
            for unit in scheduled:
                if unit in due:
                    unit.update_schedule(t, rec.next_event.get(unit) if recording else None)
            if t >= m.stop_ticks:
                break
            t_next = min(m.stop_ticks, m.next_output_ticks)
            for u in scheduled:
                if u.next_event_ticks < t_next:  # type: ignore[operator]
                    t_next = u.next_event_ticks  # type: ignore[assignment]
            for u in eventful:
                event = u.event_time()
                if event is not None and event < t_next:
                    t_next = event
            for u in limited:
                if u.time_ticks + u.max_step_ticks < t_next:
                    t_next = u.time_ticks + u.max_step_ticks
            for u in early:  # never scheduled: due at every point
                reached = u.step_to(t_next)
                if reached < t_next:
                    t_next = reached
            due = {u for u in units if not u.scheduled or u.next_event_ticks == t_next}
            for unit in late:
                if unit in due:
                    unit.step_to(t_next)
            t = t_next
            m.progress(t)
        m.finish(t)


class FixedStep(Algorithm):
    """Every FMU every base step, values flowing in dependency order (Gauss-Seidel)."""

    name = "fixed"

    def exchange(self, t: int) -> None:
        self.m.propagate(self.everyone, t)
        self.m.maybe_record(t)

    def run(self) -> None:
        m = self.m
        self.everyone: set[Unit] = set(m.units)
        k, t = 0, m.start_ticks
        while True:
            self.exchange(t)
            if t >= m.stop_ticks:
                break
            k += 1
            t = min(m.start_ticks + k * m.base_step_ticks, m.stop_ticks)
            for unit in m.units:
                unit.step_to(t)
            m.progress(t)
        m.finish(t)


class Jacobi(FixedStep):
    """Every FMU every base step from the same values: after all doSteps, read every output,
    then set every input (as libcosim does). A command reaches the plant one step later."""

    name = "jacobi"

    def exchange(self, t: int) -> None:
        m = self.m
        if not hasattr(self, "_all"):
            self._all = exchange.stage(m.links)  # one stage: all reads before all writes
        self._all.read()
        m.maybe_record(t)
        self._all.write()


ALGORITHM_CLASSES: dict[str, type[Algorithm]] = {
    cls.name: cls for cls in (EventDriven, FixedStep, Jacobi)
}
