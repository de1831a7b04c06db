"""The master: loads a scenario's FMUs, initialises and wires them, runs an algorithm over them
and keeps what the observers saw (libcosim's execution).

Values flow at each communication point in dependency order (SPEC timing contract): outputs of
FMUs without direct feedthrough (plants) -> inputs of feedthrough FMUs (controllers) -> their
outputs -> inputs of the plants, so a command computed from the measurement at t acts from t.
Time is kept in integer nanoseconds. The FMUs are :class:`cosim.run.master.unit.Unit` s of
either FMI version, side by side.
"""

from __future__ import annotations

import logging
import re
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from cosim.fmu import diagnostics as fmu_diagnostics
from cosim.fmu.state import to_seconds, to_ticks
from cosim.run import exchange, interrupt, isolation
from cosim.run.dependencies import order_connections
from cosim.run.master.algorithms import ALGORITHM_CLASSES
from cosim.run.master.errors import FmuCallError, FmuTerminated, SimulationError
from cosim.run.master.loading import open_fmu, unit_class
from cosim.run.master.observers import LIST_FAMILIES, Recorder
from cosim.run.master.pool import InstancePool, Key
from cosim.run.master.scheduled import Fmi3ScheduledUnit
from cosim.run.master.unit import Unit
from cosim.run.scenario import (
    Connection,
    Scenario,
    ScenarioError,
    blame_override,
    check_against_fmus,
    check_timing,
    unconnected_inputs,
)
from cosim.run.threads import one_blas_thread

ProgressFn = Callable[[float, float], None]
WARNING_COUNTER = "qp_infeasible"  # an FMU output counting events that needed a fallback
LOG = logging.getLogger(__name__)


@dataclass
class Link:
    """A resolved connection with value references, and its change count."""

    conn: Connection
    src: Unit
    dst: Unit
    src_name: str
    dst_name: str
    last: Any = None
    changes: int = 0
    history: list[Any] | None = None  # every new value (kept only for the summary's command)


def _expand(units: dict[str, Unit], ref: str) -> list[tuple[Unit, str]]:
    comp, var = ref.split(".", 1)
    unit = units[comp]
    if "*" not in var:
        return [(unit, var)]
    pattern = re.compile(re.escape(var).replace(r"\*", ".*") + "$")
    return [(unit, n) for n in unit.vars if pattern.match(n)]


class Master:
    """Loads the FMUs of a scenario, initialises and wires them, and runs an algorithm."""

    def __init__(self, scenario: Scenario, algorithm: str | None = None,
                 progress: ProgressFn | None = None, pool: InstancePool | None = None
                 ) -> None:
        """``pool``: where the FMU instances are taken from (reset) and given back to after
        a completed run (:mod:`cosim.run.master.pool`); without one each run instantiates
        and frees its own."""
        self.scenario = scenario
        self.pool = pool
        self.pool_keys: dict[Unit, Key] = {}
        self.reused: set[Unit] = set()  # taken from the pool: reset, not instantiated
        self.algorithm_name = algorithm or scenario.simulation.algorithm
        if self.algorithm_name not in ALGORITHM_CLASSES:
            raise ScenarioError(f"unknown algorithm {self.algorithm_name!r}; expected one of "
                                f"{sorted(ALGORITHM_CLASSES)}")
        self._progress_fn = progress
        sim = scenario.simulation
        self.start_ticks = to_ticks(sim.start_time)
        self.stop_ticks = to_ticks(sim.stop_time)
        self.output_ticks = to_ticks(sim.output_interval)
        self.next_output_ticks = self.start_ticks
        base = sim.base_step if sim.base_step is not None else sim.output_interval
        self.base_step_ticks = to_ticks(base)
        self.units: list[Unit] = []
        self.links: list[Link] = []
        self._plans: dict[frozenset[Unit], list[exchange.Stage]] = {}
        self.wall_time = 0.0

    # -- set-up --------------------------------------------------------------------------------
    def load(self) -> None:
        sc = self.scenario
        descriptions = {}
        extracted: dict[Path, str] = {}
        for comp in sc.components.values():
            if not comp.fmu_path.is_file():
                raise ScenarioError(f"{sc.path}: [fmus.{comp.name}] fmu = {comp.fmu!r}: "
                                    f"{comp.fmu_path} not found (run `cosim build`)")
            # the description and the folder of one version of the file
            descriptions[comp.name], extracted[comp.fmu_path] = (
                open_fmu(sc, comp.name, comp.fmu_path) if self.pool is None
                else self.pool.description(sc, comp.name, comp.fmu_path))
        views = {name: unit_class(md).scenario_view(md) for name, md in descriptions.items()}
        clocks = {name: {v.name for v in md.modelVariables if v.type == "Clock"}
                  for name, md in descriptions.items()}
        clock_connections = [c for c in sc.connections
                             if c.src_var in clocks.get(c.src, ()) or
                             c.dst_var in clocks.get(c.dst, ())]
        values = replace(sc, connections=[c for c in sc.connections
                                          if c not in clock_connections])
        try:
            check_against_fmus(values, views)
            check_timing(values, views, self.algorithm_name)
        except ScenarioError as err:
            raise blame_override(err, sc.path, sc.overrides) from None
        kept = unconnected_inputs(values, views)
        if kept:
            LOG.warning("%s: inputs neither connected nor set keep their start values: %s",
                        sc.path, ", ".join(f"{name}.{v.name} = {v.start}" for name, v in kept))
        by_name: dict[str, Unit] = {}
        for comp in sc.components.values():
            md = descriptions[comp.name]
            unit = None
            if self.pool is not None:
                key = self.pool.key(comp.name, comp.fmu_path, self.event_mode)
                unit = self.pool.take(key)
            if unit is None:
                unit = unit_class(md)(comp.name, comp.fmu_path, extracted[comp.fmu_path], md)
            else:
                self.reused.add(unit)
            if self.pool is not None:
                self.pool_keys[unit] = key
            if comp.sample_time is not None:
                unit.sample_ticks = to_ticks(comp.sample_time)
            if comp.max_step is not None:
                unit.max_step_ticks = to_ticks(comp.max_step)
            by_name[comp.name] = unit
            self.units.append(unit)
        self.by_name = by_name
        isolation.watch(self.units)  # in a run's child process: where a crash happened
        command = sc.summary.get("command")
        self.clock_links = self._clock_links(clock_connections)
        for c in values.connections:
            self.links.append(Link(c, by_name[c.src], by_name[c.dst], c.src_var, c.dst_var,
                                   history=[] if command == f"{c.src}.{c.src_var}" else None))
        self.link_order = self._value_flow_order()
        self.eventful: list[Unit] = []  # FMUs whose events the algorithm handles (initialize)

    def _clock_links(self, connections: list[Connection]
                     ) -> dict[Unit, dict[int, list[tuple[Unit, int]]]]:
        """Source unit -> its output clock (value reference) -> the (unit, input clock) it
        triggers, from the scenario's clock ``connections``: an output clock of an FMI 3 FMU
        (Scheduled Execution or co-simulation) to a ``triggered`` input clock of an FMI 3 FMU
        (FMI 3.0 sec. 2.2.8.2, triggered input Clock: it ticks when the importer says; of a
        Scheduled Execution FMU, sec. 5.2.2; of a co-simulation FMU, in its Event Mode, sec.
        4.2.1). Either end not a Clock of that causality, or the input clock not triggered, is
        a :class:`ScenarioError` naming the scenario file and the connection; so is a
        co-simulation FMU's triggered input clock wired to nothing (it would never tick)."""
        out: dict[Unit, dict[int, list[tuple[Unit, int]]]] = {}
        wired: set[tuple[Unit, str]] = set()
        for c in connections:
            key = f"{self.scenario.path}: [connections] \"{c.dst}.{c.dst_var}\" = " \
                  f"\"{c.src}.{c.src_var}\""
            src, dst = self.by_name[c.src], self.by_name[c.dst]
            for unit, var, causality in ((src, c.src_var, "output"), (dst, c.dst_var, "input")):
                clock = getattr(unit, "clock_names", {}).get(var)
                if clock is None or clock.causality != causality:
                    raise ScenarioError(f"{key}: {unit.name}.{var} is not an {causality} Clock "
                                        "(a Clock connects to a Clock)")
            target = dst.clock_names[c.dst_var]
            if target.interval_variability != "triggered":
                raise ScenarioError(f"{key}: {c.dst}.{c.dst_var} has intervalVariability "
                                    f"{target.interval_variability!r}: only a triggered input "
                                    "clock ticks when another clock does")
            source = src.clock_names[c.src_var].value_reference  # type: ignore[attr-defined]
            src.watch_clock(source)  # type: ignore[attr-defined]
            if not isinstance(dst, Fmi3ScheduledUnit):
                dst.take_times_from(src)  # type: ignore[attr-defined]
            wired.add((dst, c.dst_var))
            out.setdefault(src, {}).setdefault(source, []).append((dst, target.value_reference))
        for unit in self.units:
            if isinstance(unit, Fmi3ScheduledUnit):
                continue  # a partition nothing triggers never runs (sec. 5.2.2)
            for clock in getattr(unit, "input_clocks", ()):
                if clock.interval_variability == "triggered" and (unit, clock.name) not in wired:
                    comp = self.scenario.components[unit.name]
                    raise ScenarioError(
                        f"{self.scenario.path}: [fmus.{unit.name}] fmu = {comp.fmu!r}: input "
                        f"Clock {clock.name!r} is triggered (intervalVariability = "
                        "\"triggered\", FMI 3.0 sec. 2.2.8.2: it ticks only when the importer "
                        "activates it) and no output Clock is connected to it: connect one in "
                        f"[connections] (\"{unit.name}.{clock.name}\" = "
                        "\"<fmu>.<output clock>\")")
        return out

    def _deliver(self, unit: Unit, ticks: int, pending: list[Unit],
                 open_events: set[Unit]) -> None:
        """Trigger the input clocks wired to the output clocks ``unit`` ticked at ``ticks``: a
        triggered FMU not yet handled at this point is handled before its outputs are read,
        one already handled is activated again now (its outputs flow from the next point). A
        triggered co-simulation FMU is at ``ticks`` (its clock ticks in its Event Mode at the
        source's tick time, FMI 3.0 sec. 2.2.8.2, 4.2.1); one that is not is a
        :class:`SimulationError`."""
        wired = self.clock_links.get(unit)
        if not wired:
            return
        for vr in unit.take_ticks():  # type: ignore[attr-defined]
            for dst, clock in wired.get(vr, ()):
                if dst.time_ticks != ticks and not isinstance(dst, Fmi3ScheduledUnit):
                    raise SimulationError(
                        f"{unit.name}: its output clock ticked at t = {to_seconds(ticks)!r} s "
                        f"where {dst.name}, whose triggered input clock it drives, is at t = "
                        f"{to_seconds(dst.time_ticks)!r} s (FMI 3.0 sec. 2.2.8.2: the clock "
                        "ticks at the same time in both)")
                dst.trigger(clock)  # type: ignore[attr-defined]
                if dst in open_events:
                    continue
                if dst not in pending:
                    pending.append(dst)
                    open_events.add(dst)
                else:
                    dst.complete_event(ticks)
                    self._deliver(dst, ticks, pending, open_events)

    def _value_flow_order(self) -> list[Link]:
        """Connections in value-flow order by the per-variable dependency graph
        (:mod:`cosim.run.dependencies`); an algebraic loop, also of one FMU wired to itself,
        is a :class:`ScenarioError`."""
        try:
            order = order_connections([lk.conn for lk in self.links],
                                      {u.name: u.deps for u in self.units},
                                      f"{self.scenario.path}: [connections]: ")
        except ValueError as err:
            raise ScenarioError(str(err)) from err
        return [self.links[i] for i in order]

    def initialize(self) -> None:
        sc = self.scenario
        for unit in self.units:
            comp = sc.components[unit.name]
            if unit in self.reused:
                unit.reset()
            else:
                unit.instantiate(event_mode=self.event_mode)
            self._blas_refresh()  # the FMU's modules may have loaded a BLAS library
            unit.time_ticks = self.start_ticks
            params = dict(comp.parameters)
            if comp.sample_time is not None and "sample_time" in unit.vars:
                params.setdefault("sample_time", comp.sample_time)
            try:
                for name, value in {**params, **comp.inputs}.items():
                    unit.set(name, value)
                unit.enter_initialization(sc.simulation.start_time, sc.simulation.stop_time)
            except FmuCallError as err:
                raise SimulationError(f"{unit.name} ({comp.fmu}): rejected parameters: "
                                      f"{unit.fmu_reason(err.__cause__ or err)}") from err
        self.eventful = [u for u in self.units if u.has_events]
        if self.algorithm_name == "jacobi":
            # initial values flow once in initialization mode (plant outputs are valid there)
            for link in self.links:
                if not link.src.deps.get(link.src_name):
                    self.transfer(link, link.src.get([link.src_name])[0])
        for unit in self.units:
            unit.exit_initialization()

    @property
    def event_mode(self) -> bool:
        """Does the algorithm handle the FMUs' events (FMI 3 Event Mode)?"""
        return ALGORITHM_CLASSES[self.algorithm_name].event_mode

    # -- used by the algorithms ------------------------------------------------------------------
    def transfer(self, link: Link, value: Any) -> None:
        if link.last is not None and value != link.last:
            link.changes += 1
        if link.history is not None and (link.last is None or value != link.last):
            link.history.append(value)
        link.last = value
        link.dst.set(link.dst_name, value)

    def propagate(self, due: set[Unit], ticks: int) -> None:
        """Set the inputs of every due FMU from its sources, in value-flow order, as stages of
        one get per source and one set per destination (:mod:`cosim.run.exchange`); the plan
        of each set of due FMUs is built once. An FMU with an event at ``ticks`` enters Event
        Mode first (its inputs are set there) and handles the event just before its outputs
        are first read (after the inputs they depend on are set), else after every stage."""
        key = frozenset(due)
        stages = self._plans.get(key)
        if stages is None:
            stages = self._plans[key] = exchange.plan(
                [link for link in self.link_order if link.dst in due])
        pending = [u for u in self.eventful if u.event_pending(ticks)] if self.eventful else []
        if not pending:
            for st in stages:
                st.run()
            return
        for unit in pending:
            unit.begin_event(ticks)
        open_events = set(pending)
        for st in stages:
            for batch in st.reads:
                if batch.unit in open_events:
                    open_events.discard(batch.unit)
                    batch.unit.complete_event(ticks)
                    self._deliver(batch.unit, ticks, pending, open_events)
            st.run()
        for unit in pending:  # a unit triggered here is appended: handled in this loop too
            if unit in open_events:
                open_events.discard(unit)
                unit.complete_event(ticks)
                self._deliver(unit, ticks, pending, open_events)

    def output_point(self, ticks: int) -> bool:
        """Is ``ticks`` an output point (or the stop time)?"""
        return ticks >= self.next_output_ticks or ticks >= self.stop_ticks

    def advance_output(self, ticks: int) -> None:
        """The next output point after one recorded at ``ticks``."""
        while self.next_output_ticks <= ticks:
            self.next_output_ticks += self.output_ticks
        self.next_output_ticks = min(self.next_output_ticks, self.stop_ticks)

    def maybe_record(self, ticks: int) -> None:
        if self.output_point(ticks):
            self.recorder.record(ticks)
            self.advance_output(ticks)

    def progress(self, ticks: int) -> None:
        if interrupt.requested():
            interrupt.check(to_seconds(ticks))
        if self._progress_fn is not None:
            self._progress_fn(to_seconds(ticks - self.start_ticks),
                              to_seconds(self.stop_ticks - self.start_ticks))

    def finish(self, ticks: int) -> None:
        self.end_ticks = ticks

    # -- run -----------------------------------------------------------------------------------
    def run(self) -> RunResult:
        """Run to the stop time. On a failure or an interrupt the result recorded so far is
        kept in ``self.partial`` (a :class:`RunResult` with ``completed`` False)."""
        t0 = time.perf_counter()
        try:
            self.load()
        except BaseException:
            self._free_taken()
            raise
        refs = self._recorded_refs()
        n_points = int((self.stop_ticks - self.start_ticks) // self.output_ticks) + 2
        self.recorder = Recorder(refs, n_points)
        self.end_ticks = self.start_ticks
        self.partial: RunResult | None = None
        final_outputs: dict[str, dict[str, Any]] = {}
        self.terminated_by: dict[str, Any] | None = None
        self.diagnostics: dict[str, dict[str, float]] = {}
        with one_blas_thread() as self._blas_refresh:  # one BLAS thread per run
            try:
                interrupt.check(to_seconds(self.start_ticks))
                self.initialize()
                interrupt.check(to_seconds(self.start_ticks))
                loop_start, loop_cpu = time.perf_counter(), time.process_time()
                try:
                    ALGORITHM_CLASSES[self.algorithm_name](self).run()
                except FmuTerminated as stop:
                    self._end_at(stop)
                self.loop_wall_time = time.perf_counter() - loop_start
                self.loop_cpu_time = time.process_time() - loop_cpu
                final_outputs = self._final_outputs()
                for unit in self.units:
                    unit.terminate()
                    self.diagnostics[unit.name] = fmu_diagnostics.parse(unit.messages)
            except BaseException as err:
                self.end_ticks = max(u.time_ticks for u in self.units) if self.units else 0
                self.partial = self._result(final_outputs, time.perf_counter() - t0)
                self.partial.completed = False
                self.partial.error = (str(err) if isinstance(err, interrupt.Interrupted)
                                      else f"{type(err).__name__}: {err}")
                raise
            finally:
                kept = self.pool is not None and self.partial is None
                for unit in self.units:
                    try:
                        if kept:
                            self.pool.give(self.pool_keys[unit], unit)
                        else:
                            unit.free()
                    except Exception:  # noqa: BLE001 - freeing must not hide the real error
                        pass
        self.wall_time = time.perf_counter() - t0
        return self._result(final_outputs, self.wall_time)

    def _free_taken(self) -> None:
        """After a failed :meth:`load`: free the instances it took from the pool (they were
        instantiated by an earlier run); the ones it created are not instantiated yet."""
        for unit in self.reused:
            try:
                unit.free()
            except Exception:  # noqa: BLE001 - freeing must not hide the real error
                pass
        self.reused.clear()

    def _end_at(self, stop: FmuTerminated) -> None:
        """An FMU ended the simulation: a last output point at its last successful time."""
        self.terminated_by = {"instance": stop.unit.name, "time": to_seconds(stop.ticks)}
        stop.unit.time_ticks = stop.ticks
        last = self.recorder.last_time()
        if last is None or to_ticks(last) < stop.ticks:
            self.recorder.record(stop.ticks)
        self.end_ticks = stop.ticks

    def _result(self, final_outputs: dict[str, dict[str, Any]], wall_time: float) -> RunResult:
        return RunResult(
            scenario=self.scenario,
            algorithm=self.algorithm_name,
            frame=self.recorder.frame(),
            do_steps={u.name: u.do_steps for u in self.units},
            executions={u.name: int(final_outputs.get(u.name, {}).get("executions",
                                                                      u.do_steps))
                        for u in self.units},
            fmu_wall_time_s={u.name: u.wall_time for u in self.units},
            connection_changes={f"{lk.conn.src}.{lk.src_name}": lk.changes for lk in self.links},
            connection_values={f"{lk.conn.src}.{lk.src_name}": lk.history for lk in self.links
                               if lk.history is not None},
            final_outputs=final_outputs,
            wall_time_s=wall_time,
            sim_time_s=to_seconds(self.end_ticks - self.start_ticks),
            terminated_by=getattr(self, "terminated_by", None),
            diagnostics={k: v for k, v in getattr(self, "diagnostics", {}).items() if v},
        )

    def _recorded_refs(self) -> list[tuple[Unit, str]]:
        sc = self.scenario
        refs: list[str] = list(sc.record) if sc.record is not None else [
            f"{u.name}.{n}" for u in self.units for n, v in u.vars.items()
            if v.causality == "output" and v.family not in LIST_FAMILIES]
        # infeasibility counters are always recorded: the summary warns from when they rise
        refs += [f"{u.name}.{WARNING_COUNTER}" for u in self.units if WARNING_COUNTER in u.vars]
        for value in sc.summary.values():
            for ref in value if isinstance(value, list) else [value]:
                if isinstance(ref, str) and "." in ref and ref.split(".", 1)[0] in self.by_name:
                    refs.append(ref)
        seen: set[tuple[str, str]] = set()
        out: list[tuple[Unit, str]] = []
        for ref in refs:
            for unit, name in _expand(self.by_name, ref):
                if (unit.name, name) not in seen:
                    seen.add((unit.name, name))
                    out.append((unit, name))
        return out

    def _final_outputs(self) -> dict[str, dict[str, Any]]:
        out: dict[str, dict[str, Any]] = {}
        for unit in self.units:
            names = [n for n, v in unit.vars.items()
                     if v.causality == "output" and v.family not in LIST_FAMILIES]
            out[unit.name] = dict(zip(names, unit.get(names)))
        return out


@dataclass
class RunResult:
    scenario: Scenario
    algorithm: str
    frame: Any  # pandas.DataFrame, first column "time" (s)
    do_steps: dict[str, int]
    executions: dict[str, int]
    fmu_wall_time_s: dict[str, float]
    connection_changes: dict[str, int]
    final_outputs: dict[str, dict[str, Any]]
    wall_time_s: float
    sim_time_s: float
    summary: dict[str, Any] = field(default_factory=dict)
    completed: bool = True
    error: str | None = None
    terminated_by: dict[str, Any] | None = None  # {instance, time}: an FMU ended the run
    # the successive values passed on by the summary's command connection (command_switches)
    connection_values: dict[str, list[Any]] = field(default_factory=dict)
    # run-dependent figures an FMU logged at fmi2Terminate (solve times): never outputs
    diagnostics: dict[str, dict[str, float]] = field(default_factory=dict)
