"""Co-simulation master on fmpy's FMU2Slave.

Three separate concerns, each a small class:

* :class:`FmuUnit` handles one FMU instance (load, parameters, get/set, doStep, counters);
* an algorithm (:class:`EventDriven`, :class:`FixedStep`, :class:`Jacobi`) decides when each
  FMU steps and in which order values flow;
* a :class:`Recorder` stores the time series at the output points.

Values flow at each communication point in dependency order (SPEC timing contract): outputs of
FMUs without direct feedthrough (plants) -> inputs of feedthrough FMUs (controllers) -> their
outputs -> inputs of the plants, so a command computed from the measurement at t acts from t.
Time is kept in integer nanoseconds.
"""

from __future__ import annotations

import atexit
import ctypes
import math
import re
import shutil
import time
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from time import perf_counter
from typing import Any

import numpy as np
from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import (
    FMU2Slave,
    calloc,
    fmi2CallbackAllocateMemoryTYPE,
    fmi2CallbackFreeMemoryTYPE,
    fmi2CallbackFunctions,
    fmi2CallbackLoggerTYPE,
    free,
)

from cosim.fmu import diagnostics as fmu_diagnostics
from cosim.fmu.state import to_seconds, to_ticks
from cosim.run import exchange, interrupt
from cosim.run.dependencies import order_connections, output_dependencies
from cosim.run.fmi_batch import Batch
from cosim.run.fmi_types import FUNCTIONS, NUMERIC, enumeration_items, to_fmi
from cosim.run.scenario import (
    Connection,
    Scenario,
    ScenarioError,
    blame_override,
    check_against_fmus,
    check_timing,
    load_scenario,
)
from cosim.run.threads import one_blas_thread

ProgressFn = Callable[[float, float], None]
WARNING_COUNTER = "qp_infeasible"  # an FMU output counting events that needed a fallback

# One extraction per FMU file (and version) per process: pythonfmu caches the FMU's Python
# module by name, so later instances keep using the first extraction; it stays until exit.
_EXTRACTED: dict[tuple[str, float], str] = {}


def extract_once(path: Path) -> str:
    key = (str(path.resolve()), path.stat().st_mtime)
    if key not in _EXTRACTED:
        _EXTRACTED[key] = extract(str(path))
    return _EXTRACTED[key]


def warm_up(path: Path) -> None:
    """Extract ``path`` (once per process) and instantiate it once, so its bundled modules are
    imported (and shared by processes forked afterwards); failures are left to the runs."""
    try:
        md = read_model_description(str(path))
        slave = FMU2Slave(guid=md.guid, unzipDirectory=extract_once(path),
                          modelIdentifier=md.coSimulation.modelIdentifier,
                          instanceName="warm-up")
        slave.instantiate(loggingOn=False)
        slave.freeInstance()
    except Exception:  # noqa: BLE001 - the run of a point reports what is wrong
        pass


@atexit.register
def _remove_extractions() -> None:
    for d in _EXTRACTED.values():
        shutil.rmtree(d, ignore_errors=True)


class SimulationError(RuntimeError):
    """An FMU call failed during a run; the message names the FMU, the call and the time."""


def available_memory() -> int | None:
    """Bytes of memory available to a new allocation (Linux MemAvailable), None if unknown."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return None


class FmuTerminated(Exception):  # noqa: N818 - a normal end of the run, not an error
    """An FMU ended the simulation: doStep returned fmi2Discard with fmi2Terminated true
    (FMI 2.0.4 sec. 4.2.2); ``ticks`` is its fmi2LastSuccessfulTime."""

    def __init__(self, unit: FmuUnit, ticks: int) -> None:
        super().__init__(f"{unit.name} terminated the simulation at t={to_seconds(ticks)} s")
        self.unit = unit
        self.ticks = ticks


# Discard policy: a refused step is retried from the FMU's last successful time in pieces of
# half the refused size, down to 1/2**MAX_HALVINGS of the communication step.
MAX_HALVINGS = 10
_FMI2_WARNING, _FMI2_DISCARD = 1, 2
_FMI2_LAST_SUCCESSFUL_TIME, _FMI2_TERMINATED = 2, 3


def read_fmu(sc: Scenario, instance: str, path: Path) -> Any:
    """The modelDescription of the FMU of ``instance``, after checking the file is an FMU with a
    co-simulation binary for this platform: otherwise a :class:`ScenarioError` naming the
    scenario file, the instance and the path (instead of BadZipFile / KeyError later)."""
    import zipfile

    from fmpy import platform

    where = f"{sc.path}: [fmus.{instance}] fmu = {str(path)!r}"
    try:
        with zipfile.ZipFile(path) as archive:
            names = set(archive.namelist())
    except (zipfile.BadZipFile, OSError) as err:
        raise ScenarioError(f"{where}: not an FMU (not a readable zip archive: {err})") from None
    if "modelDescription.xml" not in names:
        raise ScenarioError(f"{where}: not an FMU (no modelDescription.xml in the archive)")
    try:
        md = read_model_description(str(path))
    except Exception as err:  # noqa: BLE001 - fmpy raises many kinds on a bad XML
        raise ScenarioError(f"{where}: modelDescription.xml is not valid: {err}") from None
    if md.coSimulation is None:
        raise ScenarioError(f"{where}: not a co-simulation FMU (model exchange only)")
    ident = md.coSimulation.modelIdentifier
    ext = {"linux": ".so", "darwin": ".dylib", "win": ".dll"}
    suffix = next(v for k, v in ext.items() if platform.startswith(k))
    if f"binaries/{platform}/{ident}{suffix}" not in names:
        found = sorted({n.split("/")[1] for n in names
                        if n.startswith("binaries/") and n.count("/") >= 2 and n.split("/")[1]})
        raise ScenarioError(f"{where}: no binary for this platform ({platform}; the FMU has "
                            f"{', '.join(found) or 'no binaries'})")
    return md


class FmuCallError(SimulationError):
    """An FMI call other than doStep failed; ``status`` is the FMI status (3 error, 4 fatal)."""

    def __init__(self, message: str, status: int | None = None) -> None:
        super().__init__(message)
        self.status = status


class _CheckedSlave:
    """An fmpy slave whose FMI calls (doStep aside: :meth:`FmuUnit.step_to` handles it) raise
    :class:`FmuCallError` naming the instance, the call, the time and what the FMU logged,
    instead of fmpy's bare ``FMICallException``; a failure anywhere keeps the partial results.
    Each wrapped method is built once, on first use, and then found as a plain attribute."""

    def __init__(self, slave: FMU2Slave, unit: FmuUnit) -> None:
        self._slave, self._unit = slave, unit

    def __getattr__(self, name: str) -> Any:
        attr = getattr(self._slave, name)
        if name == "doStep" or not callable(attr):
            return attr
        unit = self._unit

        def call(*args: Any, **kwargs: Any) -> Any:
            try:
                return attr(*args, **kwargs)
            except Exception as err:
                raise FmuCallError(unit.call_error_text(name, err),
                                   getattr(err, "status", None)) from err

        setattr(self, name, call)
        return call


@dataclass
class Variable:
    vr: int
    type: str
    causality: str
    items: dict[str, int] = field(default_factory=dict)  # Enumeration item name -> value


def logging_callbacks(on_message: Callable[[int, str], None]) -> fmi2CallbackFunctions:
    """fmpy FMI 2 callbacks that hand every log message (status, text) to ``on_message``.
    The caller must keep the returned object referenced while the FMU instance lives."""

    def logger(env, instance, status, category, message) -> None:
        on_message(int(status), message.decode("utf-8", "replace") if message else "")

    callbacks = fmi2CallbackFunctions()
    callbacks.logger = fmi2CallbackLoggerTYPE(logger)
    callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
    callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
    return callbacks


class FmuUnit:
    """One FMU instance: values by name, doStep accounting, scheduling information."""

    def __init__(self, name: str, path: Path, unzipdir: str, md: Any) -> None:
        self.name = name
        self.path = path
        self.md = md
        self.vars = {v.name: Variable(v.valueReference, v.type, v.causality,
                                      enumeration_items(v)) for v in md.modelVariables}
        self.slave = _CheckedSlave(FMU2Slave(guid=md.guid, unzipDirectory=unzipdir,
                                             modelIdentifier=md.coSimulation.modelIdentifier,
                                             instanceName=name), self)
        self.deps = output_dependencies(md)  # absent dependencies attribute: all inputs
        self.feedthrough = any(self.deps.values())
        self.variable_step = bool(md.coSimulation.canHandleVariableCommunicationStepSize)
        self.time_ticks = 0
        self.do_steps = 0
        self.wall_time = 0.0
        self._blas_refresh: Callable[[], None] = lambda: None  # see run()
        self.loop_wall_time = 0.0  # s, the communication points alone (benchmarks)
        self.loop_cpu_time = 0.0  # s, CPU time of this process over the same
        self.sample_ticks: int | None = None
        self.max_step_ticks: int | None = None
        self.next_event_ticks: int | None = None
        self.has_next_event_output = "next_event_time" in self.vars
        self.messages: list[str] = []
        slave = self.slave
        self._getters: dict[str, Callable[[list[int]], list[Any]]] = {
            "Real": slave.getReal, "Integer": slave.getInteger, "Boolean": slave.getBoolean,
            "String": self._read_strings}
        self._setters: dict[str, Callable[[list[int], list[Any]], None]] = {
            "Real": slave.setReal, "Integer": slave.setInteger, "Boolean": slave.setBoolean,
            "String": slave.setString}
        # kept referenced while the FMU lives
        self._callbacks = logging_callbacks(lambda status, text: self.messages.append(text))

    def instantiate(self) -> None:
        self.slave.instantiate(callbacks=self._callbacks, loggingOn=True)

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

    # -- values ------------------------------------------------------------------------------
    def read(self, family: str, vrs: list[int]) -> list[Any]:
        """One fmi2Get<family> (``Real``, ``Integer``, ``Boolean``, ``String``) of ``vrs``;
        Strings decoded."""
        t0 = perf_counter()
        values = self._getters[family](vrs)
        self.wall_time += perf_counter() - t0
        return values

    def write(self, family: str, vrs: list[int], values: list[Any]) -> None:
        """One fmi2Set<family> of ``vrs`` (values as the getters return them or as
        :func:`cosim.run.fmi_types.to_fmi` converts them)."""
        t0 = perf_counter()
        self._setters[family](vrs, values)
        self.wall_time += perf_counter() - t0

    def batch(self, family: str, vrs: list[int], setter: bool, buffer: Any = None) -> Batch:
        """A reusable fmi2Get/Set<family> of ``vrs`` (after instantiation)."""
        return Batch(self, family, vrs, setter, self.call_failed, buffer)

    def call_failed(self, call: str, status: int) -> None:
        """Raise the :class:`FmuCallError` of a failed FMI call (``call`` as fmpy names it)."""
        err = FMICallException(function=f"fmi2{call[0].upper()}{call[1:]}", status=status)
        raise FmuCallError(self.call_error_text(call, err), status) from err

    def call_error_text(self, call: str, err: BaseException) -> str:
        """The message of a failed FMI call: instance, call, time and the FMU's reason."""
        return (f"{self.name}: {call} at t = {to_seconds(self.time_ticks):g} s failed: "
                f"{self.fmu_reason(err)}")

    def _read_strings(self, vrs: list[int]) -> list[str]:
        return [v.decode("utf-8") if isinstance(v, bytes) else v
                for v in self.slave.getString(vrs)]

    def batches(self, names: list[str]) -> list[tuple[str, list[int], list[int]]]:
        """``names`` grouped by FMI function family: (family, value references, positions in
        ``names``), one FMI call each, families in first-appearance order."""
        groups: dict[str, tuple[str, list[int], list[int]]] = {}
        for i, name in enumerate(names):
            var = self.vars[name]
            group = groups.setdefault(FUNCTIONS[var.type], (FUNCTIONS[var.type], [], []))
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
        self.write(FUNCTIONS[var.type], [var.vr], [to_fmi(var.type, value, var.items)])

    def step_to(self, ticks: int) -> None:
        """doStep from this FMU's own time to ``ticks``, in steps of at most the instance's
        ``max_step`` (inputs held over them) when a master's step is longer."""
        t0 = time.perf_counter()
        try:
            while self.time_ticks < ticks:
                h = ticks - self.time_ticks
                if self.max_step_ticks:
                    h = min(h, self.max_step_ticks)
                try:
                    self._do_step(self.time_ticks, h)
                except (FmuTerminated, SimulationError):
                    raise
                except Exception as err:  # fmpy raises FMICallException with the status
                    raise SimulationError(f"{self.name}: doStep at t = "
                                          f"{to_seconds(self.time_ticks):g} s, h = "
                                          f"{to_seconds(h):g} s failed: "
                                          f"{self.fmu_reason(err)}") from err
                self.time_ticks += h
        finally:
            self.wall_time += time.perf_counter() - t0

    def _do_step(self, t: int, h: int) -> None:
        """One communication step; fmi2Discard ends the run if the FMU terminated, else the
        step is retried in smaller pieces (``MAX_HALVINGS``) if the FMU handles variable steps.
        Inputs keep the values set at ``t`` over every piece."""
        end, piece, halvings = t + h, h, 0
        while t < end:
            piece = min(piece, end - t)
            status = self._c_do_step(to_seconds(t), to_seconds(piece))
            self.do_steps += 1
            if status <= _FMI2_WARNING:
                t += piece
                continue
            if status != _FMI2_DISCARD:
                raise FMICallException(function="fmi2DoStep", status=status)
            if self._status("getBooleanStatus", _FMI2_TERMINATED, False):
                last = self._status("getRealStatus", _FMI2_LAST_SUCCESSFUL_TIME, None)
                raise FmuTerminated(self, to_ticks(last) if last is not None else t)
            if not self.variable_step:
                raise SimulationError(
                    f"{self.name}: doStep at t={to_seconds(t)} s, h={to_seconds(piece)} s "
                    "returned fmi2Discard (step refused) and the FMU cannot handle variable "
                    "communication step sizes (canHandleVariableCommunicationStepSize=false), "
                    f"so the step cannot be retried in smaller pieces: give [fmus.{self.name}] "
                    f"a smaller max_step, or a smaller base_step; FMU says: "
                    f"{self.last_messages()}")
            last = self._status("getRealStatus", _FMI2_LAST_SUCCESSFUL_TIME, None)
            if last is not None and t < to_ticks(last) < t + piece:
                t = to_ticks(last)
            halvings += 1
            if halvings > MAX_HALVINGS or piece < 2:
                raise SimulationError(
                    f"{self.name}: doStep at t={to_seconds(t)} s returned fmi2Discard for "
                    f"steps down to h={to_seconds(piece)} s ({MAX_HALVINGS} halvings of the "
                    f"communication step): giving up; FMU says: {self.last_messages()}")
            piece //= 2

    def _c_do_step(self, t: float, h: float) -> int:
        """fmi2DoStep(t, h, noSetFMUStatePriorToCurrentPoint = true): its status. The C
        function directly (the first call looks it up), or fmpy's doStep."""
        raw = self.slave._slave
        if hasattr(raw, "dll") and hasattr(raw, "component"):
            fn = raw.dll["fmi2DoStep"]  # a private function object: our argtypes
            fn.argtypes = [ctypes.c_void_p, ctypes.c_double, ctypes.c_double, ctypes.c_int]
            fn.restype = ctypes.c_int
            component = raw.component

            def do_step(t: float, h: float) -> int:
                return fn(component, t, h, 1)
        else:
            def do_step(t: float, h: float) -> int:
                try:
                    raw.doStep(currentCommunicationPoint=t, communicationStepSize=h)
                except FMICallException as err:
                    return int(err.status)
                return 0

        self._c_do_step = do_step  # type: ignore[method-assign]
        return do_step(t, h)

    def _status(self, method: str, kind: int, default: Any) -> Any:
        """fmi2Get<type>Status(kind), or ``default`` if the FMU does not provide it."""
        try:
            return getattr(self.slave, method)(kind)
        except Exception:  # noqa: BLE001 - optional in FMI 2.0 (fmi2Discard)
            return default

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


@dataclass
class Link:
    """A resolved connection with value references, and its change count."""

    conn: Connection
    src: FmuUnit
    dst: FmuUnit
    src_name: str
    dst_name: str
    last: Any = None
    changes: int = 0
    history: list[Any] | None = None  # every new value (kept only for the summary's command)


class Recorder:
    """Records named variables at output points (numbers: Real, Integer, Boolean, Enumeration
    values; String variables in lists): one FMI call per FMU and function family per output
    point, Reals read by the FMU straight into the row of a preallocated array (columns in
    read order, put in the declared order by :meth:`frame`). An FMU announcing its next event
    (``next_event_time``) has it read in the same call (:attr:`next_event`)."""

    def __init__(self, refs: list[tuple[FmuUnit, str]], n_points: int) -> None:
        self.refs = refs
        self.columns = [f"{u.name}.{n}" for u, n in refs]
        self.rows = 0
        self.strings = {col + 1: (unit, name, []) for col, (unit, name) in enumerate(refs)
                        if unit.vars[name].type == "String"}
        groups: dict[tuple[str, str], tuple[FmuUnit, str, list[int], list[int]]] = {}
        for col, (unit, name) in enumerate(refs):
            var = unit.vars[name]
            family = FUNCTIONS[var.type]
            group = groups.setdefault((unit.name, family), (unit, family, [], []))
            group[2].append(var.vr)
            group[3].append(col + 1)
        # storage: time, then each numeric group's values (+ its next_event_time) in read order
        self._groups: list[tuple[FmuUnit, str, list[int], list[int], bool, int]] = []
        width = 1
        for unit, family, vrs, cols in groups.values():
            extra = (family == "Real" and unit.has_next_event_output
                     and unit.vars["next_event_time"].type == "Real")
            if extra:
                vrs = [*vrs, unit.vars["next_event_time"].vr]
            self._groups.append((unit, family, vrs, cols, extra, width))
            if family != "String":
                width += len(vrs)
        self._width = width
        self.check_fits(n_points, width)
        self._store = np.full((n_points, width), np.nan)
        self._positions = [p for g in self._groups if g[1] != "String"
                           for p in range(g[5], g[5] + len(g[3]))]
        self._reads: list[tuple[Batch, Any, int, Any]] | None = None
        self.next_event: dict[FmuUnit, float] = {}  # read at the last sampled point

    # the store, the ordered copy :meth:`frame` makes and the pandas table built from it
    COPIES = 3

    def check_fits(self, n_points: int, width: int) -> None:
        """Refuse, before any step, a recording larger than the memory available: it needs
        ``n_points x width x 8`` bytes, :attr:`COPIES` times while the results are written."""
        need = n_points * width * 8
        available = available_memory()
        if available is not None and self.COPIES * need > available:
            raise SimulationError(
                f"the recording needs {need / 2**30:.3g} GiB ({n_points} output points x "
                f"{width} values x 8 bytes; {self.COPIES * need / 2**30:.3g} GiB with the "
                f"results table), more than the {available / 2**30:.3g} GiB of memory "
                "available: shorten [simulation] stop_time, lengthen output_interval or "
                "record fewer [record] variables")

    def bind(self) -> None:
        """Allocate the FMI calls (after the FMUs are instantiated)."""
        self._reads = []
        for unit, family, vrs, cols, extra, offset in self._groups:
            batch = unit.batch(family, vrs, False)
            target = ([self.strings[c][2] for c in cols] if family == "String"
                      else offset if batch.fast and family == "Real"
                      else slice(offset, offset + len(vrs)))
            self._reads.append((batch, target, offset + len(vrs) - 1 if extra else -1, unit))

    @property
    def data(self) -> np.ndarray:
        """The recorded rows, columns as :attr:`columns` (with time first)."""
        out = np.full((len(self._store), len(self.columns) + 1), np.nan)
        out[:, [0, *[c for g in self._groups if g[1] != "String" for c in g[3]]]] = \
            self._store[:, [0, *self._positions]]
        return out

    def sample(self, ticks: int) -> None:
        """Read the values at ``ticks`` into the next row (:meth:`commit` keeps it)."""
        if self._reads is None:
            self.bind()
        if self.rows == len(self._store):
            self._store = np.vstack([self._store, np.full_like(self._store, np.nan)])
        row = self._store[self.rows]
        row[0] = to_seconds(ticks)
        address = row.ctypes.data
        self._pending: list[tuple[list[Any], list[Any]]] = []
        for batch, target, extra, unit in self._reads:  # type: ignore[union-attr]
            if target.__class__ is int:
                batch.get(address + 8 * target)
            else:
                batch.get()
                if target.__class__ is list:
                    self._pending.append((target, batch.values()))
                else:
                    row[target] = batch.buf
            if extra >= 0:
                self.next_event[unit] = float(row[extra])

    def commit(self) -> None:
        for lists, values in self._pending:
            for column, value in zip(lists, values):
                column.append(value)
        self.rows += 1

    def record(self, ticks: int) -> None:
        self.sample(ticks)
        self.commit()

    def last_time(self) -> float | None:
        return float(self._store[self.rows - 1, 0]) if self.rows else None

    def frame(self):
        import pandas as pd

        frame = pd.DataFrame(self.data[: self.rows], columns=["time", *self.columns])
        for col, (_, _, values) in self.strings.items():
            frame[frame.columns[col]] = pd.Series(values[: self.rows], dtype=object)
        return frame


class Algorithm(ABC):
    """A stepping policy over the units of a :class:`Master`."""

    name = ""

    def __init__(self, master: Master) -> None:
        self.m = master

    @abstractmethod
    def run(self) -> None: ...


class EventDriven(Algorithm):
    """Next communication point = earliest of every scheduled FMU's next event, the output
    points, each FMU's max step and the stop time. Plants step at every point; a scheduled
    (sampled or self-triggered) FMU steps only to its own events."""

    name = "event"

    def run(self) -> None:
        m = self.m
        rec = m.recorder
        t = m.start_ticks
        units = m.units
        scheduled = [u for u in units if u.scheduled]
        limited = [u for u in units if not u.scheduled and u.max_step_ticks]
        due = set(units)
        while True:
            m.propagate(due)
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
            for u in limited:
                if u.time_ticks + u.max_step_ticks < t_next:
                    t_next = u.time_ticks + u.max_step_ticks
            due = {u for u in units if not u.scheduled or u.next_event_ticks == t_next}
            for unit in units:
                if unit in due:
                    unit.step_to(t_next)
            t = t_next
            m.progress(t)
        m.finish(t)


class FixedStep(Algorithm):
    """Every FMU every base step, values flowing in dependency order (Gauss-Seidel)."""

    name = "fixed"

    def exchange(self, t: int) -> None:
        self.m.propagate(self.everyone)
        self.m.maybe_record(t)

    def run(self) -> None:
        m = self.m
        self.everyone = set(m.units)
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


def _expand(units: dict[str, FmuUnit], ref: str) -> list[tuple[FmuUnit, str]]:
    comp, var = ref.split(".", 1)
    unit = units[comp]
    if "*" not in var:
        return [(unit, var)]
    pattern = re.compile(re.escape(var).replace(r"\*", ".*") + "$")
    return [(unit, n) for n in unit.vars if pattern.match(n)]


class Master:
    """Loads the FMUs of a scenario, initialises and wires them, and runs an algorithm."""

    def __init__(self, scenario: Scenario, algorithm: str | None = None,
                 progress: ProgressFn | None = None) -> None:
        self.scenario = scenario
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
        self.units: list[FmuUnit] = []
        self.links: list[Link] = []
        self._plans: dict[frozenset[FmuUnit], list[exchange.Stage]] = {}
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
            descriptions[comp.name] = read_fmu(sc, comp.name, comp.fmu_path)
            extracted[comp.fmu_path] = extract_once(comp.fmu_path)
        try:
            check_against_fmus(sc, descriptions)
            check_timing(sc, descriptions, self.algorithm_name)
        except ScenarioError as err:
            raise blame_override(err, sc.path, sc.overrides) from None
        by_name: dict[str, FmuUnit] = {}
        for comp in sc.components.values():
            unit = FmuUnit(comp.name, comp.fmu_path, extracted[comp.fmu_path],
                           descriptions[comp.name])
            if comp.sample_time is not None:
                unit.sample_ticks = to_ticks(comp.sample_time)
            if comp.max_step is not None:
                unit.max_step_ticks = to_ticks(comp.max_step)
            by_name[comp.name] = unit
            self.units.append(unit)
        self.by_name = by_name
        command = sc.summary.get("command")
        for c in sc.connections:
            self.links.append(Link(c, by_name[c.src], by_name[c.dst], c.src_var, c.dst_var,
                                   history=[] if command == f"{c.src}.{c.src_var}" else None))
        self.link_order = self._value_flow_order()

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
            unit.instantiate()
            self._blas_refresh()  # the FMU's modules may have loaded a BLAS library
            unit.slave.setupExperiment(startTime=sc.simulation.start_time,
                                       stopTime=sc.simulation.stop_time)
            unit.time_ticks = self.start_ticks
            params = dict(comp.parameters)
            if comp.sample_time is not None and "sample_time" in unit.vars:
                params.setdefault("sample_time", comp.sample_time)
            try:
                for name, value in {**params, **comp.inputs}.items():
                    unit.set(name, value)
                unit.slave.enterInitializationMode()
            except FmuCallError as err:
                raise SimulationError(f"{unit.name} ({comp.fmu}): rejected parameters: "
                                      f"{unit.fmu_reason(err.__cause__ or err)}") from err
        if self.algorithm_name == "jacobi":
            # initial values flow once in initialization mode (plant outputs are valid there)
            for link in self.links:
                if not link.src.deps.get(link.src_name):
                    self.transfer(link, link.src.get([link.src_name])[0])
        for unit in self.units:
            unit.slave.exitInitializationMode()

    # -- used by the algorithms ------------------------------------------------------------------
    def transfer(self, link: Link, value: Any) -> None:
        if link.last is not None and value != link.last:
            link.changes += 1
        if link.history is not None and (link.last is None or value != link.last):
            link.history.append(value)
        link.last = value
        link.dst.set(link.dst_name, value)

    def propagate(self, due: set[FmuUnit]) -> None:
        """Set the inputs of every due FMU from its sources, in value-flow order, as stages of
        one get per source and one set per destination (:mod:`cosim.run.exchange`); the plan
        of each set of due FMUs is built once."""
        key = frozenset(due)
        stages = self._plans.get(key)
        if stages is None:
            stages = self._plans[key] = exchange.plan(
                [link for link in self.link_order if link.dst in due])
        for st in stages:
            st.run()

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
        self.load()
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
                    unit.slave.terminate()
                    self.diagnostics[unit.name] = fmu_diagnostics.parse(unit.messages)
            except BaseException as err:
                self.end_ticks = max(u.time_ticks for u in self.units) if self.units else 0
                self.partial = self._result(final_outputs, time.perf_counter() - t0)
                self.partial.completed = False
                self.partial.error = (str(err) if isinstance(err, interrupt.Interrupted)
                                      else f"{type(err).__name__}: {err}")
                raise
            finally:
                for unit in self.units:
                    try:
                        unit.slave.freeInstance()
                    except Exception:  # noqa: BLE001 - freeing must not hide the real error
                        pass
        self.wall_time = time.perf_counter() - t0
        return self._result(final_outputs, self.wall_time)

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

    def _recorded_refs(self) -> list[tuple[FmuUnit, str]]:
        sc = self.scenario
        refs: list[str] = list(sc.record) if sc.record is not None else [
            f"{u.name}.{n}" for u in self.units for n, v in u.vars.items()
            if v.causality == "output" and v.type in NUMERIC]
        # infeasibility counters are always recorded: the summary warns from when they rise
        refs += [f"{u.name}.{WARNING_COUNTER}" for u in self.units if WARNING_COUNTER in u.vars]
        for value in sc.summary.values():
            for ref in value if isinstance(value, list) else [value]:
                if isinstance(ref, str) and "." in ref and ref.split(".", 1)[0] in self.by_name:
                    refs.append(ref)
        seen: set[tuple[str, str]] = set()
        out: list[tuple[FmuUnit, str]] = []
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
                     if v.causality == "output" and v.type != "String"]
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

    def write(self, out_dir: Path, plot: bool = True, force: bool = False) -> list[Path]:
        from cosim.run.results import write_results

        return write_results(self, Path(out_dir), plot=plot, force=force)


def run_scenario(scenario: str | Path | Scenario, overrides: dict[str, Any] | list[str] | None
                 = None, algorithm: str | None = None, out_dir: str | Path | None = None,
                 progress: ProgressFn | None = None, build: bool = True,
                 plot: bool = True, force: bool = False) -> RunResult:
    """Load (and override) a scenario, build missing or stale FMUs, run it, compute the summary
    and, with ``out_dir``, write results.csv, summary.json and plot.png (see
    :func:`cosim.run.results.write_results` for ``force``). A failure raises
    :class:`SimulationError`, SIGINT/SIGTERM :class:`cosim.run.interrupt.Interrupted`, both
    after writing the partial results."""
    from cosim.run.metrics import compute_summary

    sc = scenario if isinstance(scenario, Scenario) else load_scenario(scenario, overrides)
    if build:
        ensure_built(sc)
    master = Master(sc, algorithm, progress)
    # SIGINT/SIGTERM only set a flag while the FMUs run (never an exception inside their code);
    # the master stops at the next communication point and what was recorded is written
    with interrupt.guard():
        try:
            result = master.run()
        except (SimulationError, interrupt.Interrupted, KeyboardInterrupt) as err:
            partial = getattr(master, "partial", None)
            interrupted = isinstance(err, (interrupt.Interrupted, KeyboardInterrupt))
            if out_dir is None or partial is None or partial.frame.empty and not interrupted:
                raise  # a failure before anything was recorded (e.g. a rejected parameter)
            partial.summary = compute_summary(partial)
            where = partial.write(Path(out_dir), plot=plot, force=force)[0].parent
            note = (f"; partial results up to t = {partial.sim_time_s:g} s written to {where} "
                    f"(summary.json has \"completed\": false)")
            if isinstance(err, interrupt.Interrupted):
                raise interrupt.Interrupted(f"{err}{note}") from err
            if isinstance(err, KeyboardInterrupt):
                raise interrupt.Interrupted(f"{partial.error}{note}") from err
            raise SimulationError(f"{err}{note}") from err
        result.summary = compute_summary(result)
        if out_dir is not None:
            result.write(Path(out_dir), plot=plot, force=force)
    return result


def ensure_built(sc: Scenario) -> list[Path]:
    """Build the scenario's catalog FMUs that are missing or older than their sources."""
    from cosim.fmu.build import FMU_DIR, build_stale, catalog

    specs = catalog()
    wanted = [specs[c.fmu] for c in sc.components.values()
              if c.fmu in specs and c.fmu_path.parent == FMU_DIR]
    return build_stale(wanted)
