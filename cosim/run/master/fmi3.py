"""The FMI 3.0 co-simulation unit on fmpy's ``FMU3Slave`` (FMI 3.0 sec. 4).

* Types: Float64/32, Int8..UInt64, Boolean, String, Binary (bytes), Enumeration (its Int64
  functions, FMI 3.0 sec. 2.2.7.2). An array variable ``x`` of n elements appears as the
  variables ``x[1]`` .. ``x[n]`` (the FMI 2 flattening, so ``x[*]`` globs match); an element
  is read and written through the whole array (one get, or one get and one set).
* Event Mode (sec. 2.3.5; fmi3EnterEventMode and fmi3DoStep: sec. 4.2.1), when the
  algorithm handles events and the FMU ``hasEventMode``: after initialisation and at every
  event the master calls fmi3UpdateDiscreteStates until no update is needed;
  ``nextEventTimeDefined`` / ``nextEventTime`` make that time a communication point with an
  event; a doStep returning ``eventHandlingNeeded`` gives an event at the time reached; early
  return (``earlyReturnAllowed``, sec. 4.1.3) ends the communication point at
  ``lastSuccessfulTime``; ``terminateSimulation`` ends the run (:class:`FmuTerminated`).
* Event times: the master's schedule is in integer nanoseconds, the FMU's own times are
  doubles. An announced ``nextEventTime``, a clock tick or a ``lastSuccessfulTime`` that is
  not a whole nanosecond (1/3 s) is kept as the FMU's double: its communication point is the
  nearest nanosecond (the next one when that is not later than now), and the FMU is stepped
  exactly to its double (``currentCommunicationPoint + communicationStepSize`` equal to it)
  and from it.
* Input clocks (sec. 2.2.8), attributes read from modelDescription.xml
  (:func:`clock_attributes`; fmpy does not fill them), each asked of the FMU where sec.
  2.2.8.2 (Clock Types) says: a periodic clock ticks at start + shift + k interval, with
  interval and shift from the modelDescription (``constant``, and a ``fixed`` or
  ``tunable`` clock that declares its interval: ``intervalDecimal`` / ``shiftDecimal``, or
  ``intervalCounter`` / ``shiftCounter`` over ``resolution``; the master sets no interval)
  or asked of the FMU in Initialization Mode (a ``fixed`` or ``tunable`` clock that declares
  no interval: fmi3GetIntervalDecimal / fmi3GetShiftDecimal, the Fraction variants when
  ``supportsFraction``); such a ``tunable`` clock's interval is asked again in every Event
  Mode and, when the FMU says ``fmi3IntervalChanged``, it ticks next that long after its
  last tick; a ``countdown`` clock's interval is asked in Initialization Mode (its first
  tick that long after the start time, 0 included) and in every Event Mode after
  fmi3UpdateDiscreteStates, and, when the FMU says ``fmi3IntervalChanged``, it ticks once
  that long after the event (0: at the event itself, the clock set and
  fmi3UpdateDiscreteStates called again); a ``changing`` clock likewise, its interval asked
  in Initialization Mode and in each Event Mode where it ticked. Times are exact fractions
  until rounded to the FMU's double. A tick is an event where the master activates the clock
  (fmi3SetClock) before fmi3UpdateDiscreteStates.
  Output clocks tick at the FMU's events (``eventHandlingNeeded`` or ``nextEventTime``);
  those wired in the scenario to a triggered input clock (sec. 2.2.8.2, in FMI 3.0.2's
  words: "The timing could be given by a triggered output Clock ... of a connected FMU") are
  asked with fmi3GetClock in Event Mode before each fmi3UpdateDiscreteStates (sec. 2.3.5: a
  clock active during fmi3UpdateDiscreteStates is deactivated by the FMU itself).
* A ``triggered`` input clock (sec. 2.2.8.2: it ticks when the importer says, here when the
  output clock wired to it in the scenario does) ticks at the source FMU's event, where this
  FMU is at the same communication point (:meth:`Fmi3Unit.trigger`): it enters Event Mode
  (fmi3EnterEventMode, sec. 4.2.1), the clock is activated (fmi3SetClock, sec. 2.2.8.4; only
  in Event Mode, sec. 2.3.5), its inputs are set from the values after the source's event,
  then fmi3UpdateDiscreteStates (sec. 2.3.5) before its outputs are read; its time there is
  the source's own double (:meth:`Fmi3Unit.take_times_from`). A triggered input clock wired
  to nothing is refused (:mod:`cosim.run.master.core`). An FMU with input clocks is
  scheduled by their ticks alone:
  an output named ``next_event_time`` (the FMI 2 convention of :mod:`cosim.run.master.unit`)
  is not read as its next event.
"""

from __future__ import annotations

import copy
import ctypes
import io
import math
import zipfile
from collections.abc import Callable
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path
from time import perf_counter
from typing import Any
from xml.etree import ElementTree

from fmpy.fmi1 import FMICallException
from fmpy.fmi3 import FMU3Slave, fmi3IntervalChanged, fmi3IntervalNotYetKnown

from cosim.fmu.state import to_seconds, to_ticks
from cosim.run.fmi_types import enumeration_items
from cosim.run.master.errors import FmuCallError, FmuTerminated, SimulationError
from cosim.run.master.fmi2 import CheckedSlave
from cosim.run.master.unit import Unit, Variable

NUMBERS = ("Float64", "Float32", "Int8", "UInt8", "Int16", "UInt16", "Int32", "UInt32",
           "Int64", "UInt64")
C_NUMBER_TYPES = {"Float64": ctypes.c_double, "Float32": ctypes.c_float,
                  "Int8": ctypes.c_int8, "UInt8": ctypes.c_uint8, "Int16": ctypes.c_int16,
                  "UInt16": ctypes.c_uint16, "Int32": ctypes.c_int32, "UInt32": ctypes.c_uint32,
                  "Int64": ctypes.c_int64, "UInt64": ctypes.c_uint64,
                  "Boolean": ctypes.c_bool}
ARRAY = "Array"  # the family of array elements (read and written through their array)
MAX_EVENT_ITERATIONS = 1000  # fmi3UpdateDiscreteStates calls at one event before giving up
_WARNING, _DISCARD = 1, 2
# FMI 3.0 sec. 2.4.4 (ClockType attributes) and fmi3AttributeGroups.xsd (fmi3ClockAttributes);
# "calculated" is not one of them
INTERVAL_VARIABILITIES = ("constant", "fixed", "tunable", "changing", "countdown", "triggered")
PERIODIC = ("constant", "fixed", "tunable")
ASKED = ("fixed", "tunable")  # interval and shift asked of the FMU
TYPE_OWN = ("name", "description")  # a ClockType's attributes that are not its clocks'


@dataclass(frozen=True)
class ClockAttributes:
    """A Clock variable's attributes (FMI 3.0 sec. 2.4.4): interval and shift in s, exact
    (None: not declared)."""

    name: str
    value_reference: int
    causality: str
    interval_variability: str
    interval: Fraction | None
    shift: Fraction | None
    supports_fraction: bool
    # Scheduled Execution: the priority of the clock's model partition (lower value = higher
    # priority, FMI 3.0 sec. 2.4.4); None: not declared
    priority: int | None = None


def clock_attributes(path: Path) -> dict[int, ClockAttributes]:
    """The Clock variables of the FMU at ``path`` by value reference, from its
    modelDescription.xml: a Clock with a ``declaredType`` takes the attributes of that
    ``ClockType`` (TypeDefinitions) it does not declare itself (FMI 3.0 sec. 2.4.4: the
    variable's attributes override its type's); a value that is not valid is a
    :class:`SimulationError` naming the file, the variable and the attribute."""
    with zipfile.ZipFile(path) as archive:
        root = ElementTree.fromstring(archive.read("modelDescription.xml"))
    types = clock_types(root)
    clocks = []
    for element in root.iterfind("ModelVariables/Clock"):
        declared = element.get("declaredType")
        if declared is not None and declared not in types:
            raise SimulationError(f"{path}: modelDescription.xml: Clock "
                                  f"{element.get('name', '?')!r} declaredType = {declared!r}: "
                                  f"no ClockType of that name in TypeDefinitions "
                                  f"(ClockTypes: {sorted(types)})")
        clocks.append(read_clock(path, declared_attributes(types, element)))
    return {c.value_reference: c for c in clocks}


def clock_types(root: ElementTree.Element) -> dict[str | None, dict[str, str]]:
    """The ClockTypes of a modelDescription ``root`` by name: the attributes they give their
    clocks (FMI 3.0 sec. 2.4.4)."""
    return {t.get("name"): {k: v for k, v in t.attrib.items() if k not in TYPE_OWN}
            for t in root.iterfind("TypeDefinitions/ClockType")}


def declared_attributes(types: dict[str | None, dict[str, str]],
                        clock: ElementTree.Element) -> dict[str, str]:
    """The attributes of the Clock element ``clock``: its declared type's (from ``types``,
    :func:`clock_types`) overridden by its own."""
    return {**types.get(clock.get("declaredType"), {}), **clock.attrib}


def read_clock(path: Path, a: dict[str, str]) -> ClockAttributes:
    """The :class:`ClockAttributes` of one Clock element of the FMU at ``path``, from its
    attributes ``a`` (its ClockType's resolved, :func:`declared_attributes`), checked against
    FMI 3.0 sec. 2.4.4 (a known ``intervalVariability``; ``intervalDecimal`` and
    ``resolution`` > 0, ``shiftDecimal`` >= 0; a ``constant`` clock declares its interval;
    ``intervalCounter`` / ``shiftCounter`` need a ``resolution``; ``supportsFraction`` a
    boolean; ``priority`` >= 0; ``valueReference``, sec. 2.4.7.4, an unsigned integer): a
    value that is not valid is a :class:`SimulationError` naming the file, the clock and the
    attribute."""
    name = a.get("name", "?")

    def bad(key: str, why: str) -> SimulationError:
        return SimulationError(f"{path}: modelDescription.xml: Clock {name!r} {key} = "
                               f"{a.get(key)!r}: {why}")

    def number(key: str, kind: type, minimum: float, strict: bool) -> Any:
        if key not in a:
            return None
        try:
            value = kind(a[key])
        except ValueError:
            raise bad(key, f"not a valid {kind.__name__}") from None
        if not (value > minimum if strict else value >= minimum) or \
                not math.isfinite(value):
            raise bad(key, f"must be {'>' if strict else '>='} {minimum}")
        return value

    kind = a.get("intervalVariability")
    if kind not in INTERVAL_VARIABILITIES:
        raise bad("intervalVariability", f"expected one of {list(INTERVAL_VARIABILITIES)}")
    interval_decimal = number("intervalDecimal", float, 0.0, True)
    shift_decimal = number("shiftDecimal", float, 0.0, False)
    interval_counter = number("intervalCounter", int, 0, True)
    shift_counter = number("shiftCounter", int, 0, False)
    resolution = number("resolution", int, 0, True)
    if (interval_counter is not None or shift_counter is not None) and resolution is None:
        raise bad("resolution", "intervalCounter / shiftCounter need a resolution")
    interval = (Fraction(interval_counter, resolution) if interval_counter is not None
                else Fraction(interval_decimal) if interval_decimal is not None else None)
    shift = (Fraction(shift_counter, resolution) if shift_counter is not None
             else Fraction(shift_decimal) if shift_decimal is not None else None)
    if kind == "constant" and interval is None:
        raise bad("intervalDecimal", "a constant clock declares its interval "
                                     "(intervalDecimal, or intervalCounter and resolution)")
    fraction = a.get("supportsFraction", "false")
    if fraction not in ("true", "false"):
        raise bad("supportsFraction", "expected true or false")
    try:
        vr = int(a["valueReference"])
    except (KeyError, ValueError):
        raise bad("valueReference", "not an unsigned integer") from None
    return ClockAttributes(name, vr, a.get("causality", "local"), kind, interval, shift,
                           fraction == "true", number("priority", int, 0, False))


def resolved_description(path: Path) -> io.BytesIO | None:
    """An archive holding only the modelDescription.xml of the FMU at ``path`` with each Clock's
    declared ClockType resolved (:func:`declared_attributes`, ``declaredType`` dropped), for
    fmpy, which refuses (0.3.32) a Clock whose declaredType is a ClockType; None when the FMU
    has no ClockType. ``path``: the FMU file or the folder it is extracted into."""
    if Path(path).is_dir():
        xml = (Path(path) / "modelDescription.xml").read_bytes()
    else:
        with zipfile.ZipFile(path) as archive:
            xml = archive.read("modelDescription.xml")
    if b"ClockType" not in xml:
        return None
    root = ElementTree.fromstring(xml)
    types = clock_types(root)
    for clock in root.iterfind("ModelVariables/Clock"):
        if clock.get("declaredType") in types:
            attributes = declared_attributes(types, clock)
            del attributes["declaredType"]
            clock.attrib = attributes
    resolved = io.BytesIO()
    with zipfile.ZipFile(resolved, "w") as archive:
        archive.writestr("modelDescription.xml", ElementTree.tostring(root))
    return resolved


def read_model_description(path: Path, **options: Any) -> Any:
    """fmpy's modelDescription of the FMU at ``path``, a file or the folder it is extracted
    into (``options`` to
    :func:`fmpy.read_model_description`), read from :func:`resolved_description` when the FMU
    has ClockTypes."""
    from fmpy import read_model_description as fmpy_read

    return fmpy_read(resolved_description(path) or str(path), **options)


def family_of(kind: str) -> str:
    return "Int64" if kind == "Enumeration" else kind


def elements(md: Any) -> list[tuple[Any, str, int | None, int]]:
    """(fmpy variable, name, element index or None, array size) of every non-Clock variable;
    an array's elements are ``name[1]`` ... (row-major, FMI 3.0 sec. 2.2.7.1)."""
    out = []
    for v in md.modelVariables:
        if v.type == "Clock":
            continue
        size = math.prod(getattr(v, "shape", ()) or ())
        if getattr(v, "dimensions", None):
            out += [(v, f"{v.name}[{i + 1}]", i, size) for i in range(size)]
        else:
            out.append((v, v.name, None, 1))
    return out


def scenario_view(md: Any) -> Any:
    """``md`` as the scenario checks see it: array elements as variables, no clocks."""
    view = copy.copy(md)
    variables = []
    for v, name, index, size in elements(md):
        if index is None:
            variables.append(v)
        else:
            element = copy.copy(v)
            element.name = name
            starts = str(v.start).split() if v.start is not None else []
            element.start = starts[index] if len(starts) == size else None
            variables.append(element)
    view.modelVariables = variables
    return view


class Fmi3Unit(Unit):
    """An FMI 3.0 co-simulation FMU instance."""

    fmi_version = "3.0"
    # input clocks without a schedule of their own that the master ticks (sec. 2.2.8.2: the
    # FMU gives a countdown or changing clock's intervals; a triggered one ticks when an
    # output clock wired to it does)
    UNSCHEDULED_CLOCKS: tuple[str, ...] = ("countdown", "changing", "triggered")
    C_TYPES = C_NUMBER_TYPES
    C_PREFIX = "fmi3"
    C_COUNTS = True

    def __init__(self, name: str, path: Path, unzipdir: str, md: Any) -> None:
        self._arrays: dict[int, tuple[int, str, int, int]] = {}  # element id -> array info
        super().__init__(name, path, unzipdir, md)
        self.slave = CheckedSlave(self._open(md, unzipdir), self)
        self.can_event_mode = self._has_event_mode(md)
        clocks = (list(clock_attributes(path).values())
                  if any(v.type == "Clock" for v in md.modelVariables) else [])
        self.input_clocks = [c for c in clocks if c.causality == "input"]
        self.output_clocks = [c for c in clocks if c.causality == "output"]
        self.clock_names = {c.name: c for c in clocks}
        # output clocks wired to other FMUs' input clocks (:meth:`watch_clock`), and those of
        # them that ticked at the last event (:meth:`take_ticks`)
        self.watched_clocks: list[int] = []
        # FMUs whose output clocks trigger input clocks of this one: their own times (s) at
        # communication points that are not whole nanoseconds are this FMU's there too
        self.time_sources: list[Fmi3Unit] = []
        if self.input_clocks:  # its events are its Clocks' ticks, not a next_event_time output
            self.has_next_event_output = False
        self.event_mode = False
        self._reset_event_state()
        self._expand_dependencies()
        slave = self.slave
        self._getters: dict[str, Callable[[list[int]], list[Any]]] = {
            kind: getattr(slave, f"get{kind}") for kind in (*NUMBERS, "Boolean", "Binary")}
        self._getters["String"] = self._read_strings
        self._getters[ARRAY] = self._read_elements
        self._setters: dict[str, Callable[[list[int], list[Any]], None]] = {
            kind: getattr(slave, f"set{kind}")
            for kind in (*NUMBERS, "Boolean", "Binary", "String")}
        self._setters[ARRAY] = self._write_elements

    scenario_view = staticmethod(scenario_view)

    def _reset_event_state(self) -> None:
        """The run-dependent event state, as before the first run: clocks ticked, Event Mode
        entered or needed, the announced event, the FMU's exact times and the clocks'
        schedules."""
        self.ticked: list[int] = []
        self._triggered: list[int] = []  # triggered input clocks set at this point
        self._in_event = False
        self._needs_event = False
        self._announced: int | None = None
        self._exact: dict[int, float] = {}  # ticks -> the FMU's own time there (s), not whole ns
        self._clock_next: dict[int, int | None] = {}
        # periodic clock vr -> (origin s, interval s, index of its next tick k)
        self._clock_period: dict[int, tuple[Fraction, Fraction, int]] = {}

    FMPY_CLASS: type = FMU3Slave  # fmpy's class of this interface
    INTERFACE = "coSimulation"  # the modelDescription's interface element (fmpy's attribute)

    def _open(self, md: Any, unzipdir: str) -> Any:
        """The fmpy object of this instance's interface (not instantiated)."""
        return self.FMPY_CLASS(guid=md.guid, unzipDirectory=unzipdir,
                               modelIdentifier=getattr(md, self.INTERFACE).modelIdentifier,
                               instanceName=self.name)

    @staticmethod
    def _has_event_mode(md: Any) -> bool:
        return bool(md.coSimulation.hasEventMode)

    def variables(self, md: Any) -> dict[str, Variable]:
        out: dict[str, Variable] = {}
        for v, name, index, size in elements(md):
            if index is None:
                out[name] = Variable(v.valueReference, v.type, v.causality,
                                     enumeration_items(v), family_of(v.type))
            else:
                key = len(self._arrays)
                self._arrays[key] = (v.valueReference, family_of(v.type), index, size)
                out[name] = Variable(key, v.type, v.causality, enumeration_items(v), ARRAY,
                                     (size, index))
        return out

    def _expand_dependencies(self) -> None:
        """Output dependencies by element name (an array depends as a whole)."""
        names: dict[str, list[str]] = {}
        for _, name, index, _ in elements(self.md):
            base = name.rsplit("[", 1)[0] if index is not None else name
            names.setdefault(base, []).append(name)
        deps: dict[str, set[str]] = {}
        for out, inputs in self.deps.items():
            flat = {n for i in inputs for n in names.get(i, [i])}
            for element in names.get(out, [out]):
                deps[element] = flat
        self.deps = deps
        self.feedthrough = any(deps.values())

    def raw_slave(self) -> Any:
        return self.slave._slave

    # -- life cycle ----------------------------------------------------------------------------
    def instantiate(self, event_mode: bool = False) -> None:
        self.event_mode = event_mode and self.can_event_mode
        if self.input_clocks and not self.event_mode:
            names = ", ".join(c.name for c in self.input_clocks)
            why = ("the FMU has no Event Mode (hasEventMode is false)" if not self.can_event_mode
                   else "this algorithm does not handle events")
            raise SimulationError(f"{self.name}: input clocks ({names}) tick only in Event Mode "
                                  f"and {why}: run with algorithm = \"event\"")
        self.has_events = self.event_mode
        self.may_return_early = self.event_mode

        def log(env: Any, status: int, category: Any, message: Any) -> None:
            self.messages.append(message.decode("utf-8", "replace") if message else "")

        try:
            self.slave.instantiate(loggingOn=True, eventModeUsed=self.event_mode,
                                   earlyReturnAllowed=self.event_mode, logMessage=log)
        except FmuCallError as err:  # fmpy: "Failed to instantiate FMU" (the FMU gave NULL)
            raise SimulationError(self._refused_instantiation()) from err

    def _refused_instantiation(self) -> str:
        """Why fmi3InstantiateCoSimulation returned NULL: its arguments, the FMU's words, and,
        with Event Mode asked for, that the modelDescription declares it (FMI 3.0 sec. 2.3.1:
        eventModeUsed = true only if hasEventMode = true, which the binary then accepts)."""
        text = (f"{self.name} ({self.path}): fmi3InstantiateCoSimulation(eventModeUsed = "
                f"{str(self.event_mode).lower()}, earlyReturnAllowed = "
                f"{str(self.event_mode).lower()}) returned NULL: "
                f"{self.last_messages() or 'the FMU gave no reason'}")
        if self.event_mode:
            text += ("; its modelDescription.xml declares hasEventMode = true, so the event "
                     "algorithm asked for Event Mode, which its binary refuses (FMI 3.0 sec. "
                     "2.3.1, 4.4: an FMU declaring hasEventMode accepts eventModeUsed = "
                     "true): run it with algorithm = \"fixed\" (no Event Mode), or fix the "
                     "FMU")
        return text

    def enter_initialization(self, start: float, stop: float) -> None:
        self._start_ticks = to_ticks(start)
        self.slave.enterInitializationMode(startTime=start, stopTime=stop)

    def exit_initialization(self) -> None:
        periods = self._periods() if self.event_mode else {}
        first = self._first_aperiodic() if self.event_mode else {}
        self.slave.exitInitializationMode()
        if self.event_mode:  # FMI 3.0 sec. 2.3.3: now in Event Mode
            self._in_event = True
            start = Fraction(to_seconds(self._start_ticks))
            for clock in self.input_clocks:
                vr = clock.value_reference
                self._clock_next[vr] = None
                if vr in periods:
                    origin = start + periods[vr][1]
                    self._clock_period[vr] = (origin, periods[vr][0], 0)
                    self._clock_next[vr] = self._schedule(float(origin), self._start_ticks - 1)
                elif vr in first:  # sec. 2.2.8.2, aperiodic Clock: t_0 = t_start + interval
                    self._clock_next[vr] = self._schedule(float(start + first[vr]),
                                                          self._start_ticks - 1)

    def _first_aperiodic(self) -> dict[int, Fraction]:
        """The first interval (s) of every countdown and changing input clock the FMU gives
        one for, asked in Initialization Mode (FMI 3.0 sec. 2.2.8.2: the importer calls
        fmi3GetInterval for such a Clock in Initialization Mode; its first tick is t_0 =
        t_start + T_interval,0 with T_interval,0 >= 0): those with the qualifier
        ``fmi3IntervalChanged`` (none is due for another qualifier); an interval below 0 is a
        :class:`SimulationError`."""
        aperiodic = [c for c in self.input_clocks
                     if c.interval_variability in ("countdown", "changing")]
        out = {}
        for clock, (interval, qualifier) in zip(aperiodic, self._intervals(aperiodic)):
            if qualifier != fmi3IntervalChanged:
                continue
            if interval < 0:
                raise SimulationError(f"{self.name}: {clock.interval_variability} clock "
                                      f"{clock.name}: "
                                      f"fmi3GetIntervalDecimal in Initialization Mode gave "
                                      f"{float(interval)!r} s (must be >= 0)")
            out[clock.value_reference] = interval
        return out

    def _periods(self) -> dict[int, tuple[Fraction, Fraction]]:
        """(interval, shift) in s of every periodic input clock, in Initialization Mode: from
        the modelDescription (constant, and fixed or tunable with a declared interval: FMI 3.0
        sec. 2.2.8.2, the declared values hold when the importer sets none) or asked of the
        FMU (fixed, tunable without one); a clock the master cannot tick is a
        :class:`SimulationError`."""
        out = {}
        for clock in self.input_clocks:
            kind = clock.interval_variability
            if kind == "constant" or (kind in ASKED and clock.interval is not None):
                out[clock.value_reference] = (clock.interval, clock.shift or Fraction(0))
            elif kind in ASKED:
                (interval, qualifier), = self._intervals([clock])
                if qualifier == fmi3IntervalNotYetKnown:
                    raise SimulationError(f"{self.name}: {kind} clock {clock.name}: "
                                          "fmi3GetInterval says fmi3IntervalNotYetKnown at the "
                                          "end of Initialization Mode")
                out[clock.value_reference] = (interval, self._shift(clock))
            elif kind not in self.UNSCHEDULED_CLOCKS:
                raise SimulationError(f"{self.name}: input clock {clock.name} has "
                                      f"intervalVariability {kind!r}: the master ticks "
                                      "periodic (constant, fixed, tunable) and "
                                      f"{' and '.join(self.UNSCHEDULED_CLOCKS)} clocks only")
            if kind in PERIODIC and not out[clock.value_reference][0] > 0:
                raise SimulationError(f"{self.name}: periodic clock {clock.name} has interval "
                                      f"{float(out[clock.value_reference][0])!r} s (must be "
                                      "positive)")
        return out

    def terminate(self) -> None:
        self.slave.terminate()

    def free(self) -> None:
        self.slave.freeInstance()

    reusable = True

    def reset(self) -> None:
        """fmi3Reset (FMI 3.0: the instance as if just made by fmi3Instantiate<Interface>,
        every variable at its start value, with the instantiation's own arguments: Event Mode
        used or not, early return), and this side's run state as before the first run; the
        clocks other FMUs watch stay, as the scenario's connections do."""
        self.reset_run_state()
        self._reset_event_state()
        self.slave.reset()

    def get_state(self) -> Any:
        return self.slave.getFMUState()

    def set_state(self, state: Any) -> None:
        self.slave.setFMUState(state)

    # -- values ------------------------------------------------------------------------------
    def read(self, family: str, vrs: list[int]) -> list[Any]:
        t0 = perf_counter()
        values = self._getters[family](vrs)
        self.wall_time += perf_counter() - t0
        return list(values)

    def write(self, family: str, vrs: list[int], values: list[Any]) -> None:
        t0 = perf_counter()
        self._setters[family](vrs, values)
        self.wall_time += perf_counter() - t0

    def _read_strings(self, vrs: list[int]) -> list[str]:
        return [v.decode("utf-8") if isinstance(v, bytes) else v
                for v in self.slave.getString(vrs)]

    def _whole(self, vr: int, family: str, size: int) -> list[Any]:
        if family == "String":
            return [v.decode("utf-8") if isinstance(v, bytes) else v
                    for v in self.slave.getString([vr], nValues=size)]
        return list(getattr(self.slave, f"get{family}")([vr], nValues=size))

    def _read_elements(self, keys: list[int]) -> list[Any]:
        arrays: dict[int, list[Any]] = {}
        out = []
        for key in keys:
            vr, family, index, size = self._arrays[key]
            if vr not in arrays:
                arrays[vr] = self._whole(vr, family, size)
            out.append(arrays[vr][index])
        return out

    def _write_elements(self, keys: list[int], values: list[Any]) -> None:
        arrays: dict[int, tuple[str, list[Any]]] = {}
        for key, value in zip(keys, values):
            vr, family, index, size = self._arrays[key]
            if vr not in arrays:
                arrays[vr] = (family, self._whole(vr, family, size))
            arrays[vr][1][index] = value
        for vr, (family, whole) in arrays.items():
            getattr(self.slave, f"set{family}")([vr], whole)

    # -- stepping ----------------------------------------------------------------------------
    def _seconds(self, ticks: int) -> float:
        """The FMU's own time (s) at the communication point ``ticks``."""
        exact = self._exact_at(ticks)
        return to_seconds(ticks) if exact is None else exact

    def _exact_at(self, ticks: int) -> float | None:
        """The FMU's own time (s) at ``ticks`` when it is not whole nanoseconds (its own,
        else that of a :attr:`time_sources` FMU), else None."""
        exact = self._exact.get(ticks)
        for source in self.time_sources:
            if exact is not None:
                break
            exact = source._exact.get(ticks)
        return exact

    def take_times_from(self, source: Fmi3Unit) -> None:
        """``source``'s output clocks trigger input clocks of this FMU: at a communication
        point that is not a whole nanosecond this FMU's time is ``source``'s own double, so a
        triggered clock ticks at the source's tick time exactly."""
        if source is not self and source not in self.time_sources:
            self.time_sources.append(source)

    def _schedule(self, seconds: float, after: int) -> int:
        """The communication point (ticks, later than ``after``) of an event the FMU has at
        ``seconds``; a time that is not a whole nanosecond is kept as the FMU's time there."""
        ticks = max(to_ticks(seconds), after + 1)
        if seconds != to_seconds(ticks):
            self._exact[ticks] = min(seconds, self._exact.get(ticks, math.inf))
        return ticks

    def _do_step(self, t: int, h: int) -> int:
        if (self._exact or self.time_sources) and (
                self._exact_at(t) is not None or self._exact_at(t + h) is not None):
            start, end = self._seconds(t), self._seconds(t + h)
            size = end - start
            for _ in range(4):  # the FMU computes start + size: make it end exactly
                reached_s = start + size
                if reached_s == end:
                    break
                size = math.nextafter(size, math.inf if reached_s < end else -math.inf)
            for old in [k for k in self._exact if k < t]:
                del self._exact[old]
        else:
            start, size = to_seconds(t), to_seconds(h)
        status = self._c_do_step(start, size)
        self.do_steps += 1
        event, terminate, early, last = (f.value for f in self._flags)
        if status > _DISCARD:
            raise FMICallException(function="fmi3DoStep", status=status)
        if terminate:
            raise FmuTerminated(self, to_ticks(last) if status == _DISCARD or early
                                else t + h)
        if status == _DISCARD:
            raise SimulationError(f"{self.name}: doStep at t={to_seconds(t)} s, "
                                  f"h={to_seconds(h)} s returned fmi3Discard (step refused, "
                                  "no terminateSimulation): give [fmus."
                                  f"{self.name}] a smaller max_step, or a smaller base_step; "
                                  f"FMU says: {self.last_messages()}")
        self.returned_early = bool(early) and self.event_mode
        reached = self._schedule(last, t) if self.returned_early else t + h
        if self.returned_early and not (start < last and reached <= t + h):
            raise SimulationError(f"{self.name}: doStep at t={to_seconds(t)} s returned early "
                                  f"at lastSuccessfulTime = {last!r} s, outside "
                                  f"({to_seconds(t)}, {to_seconds(t + h)}] s")
        if event and self.event_mode:
            self._needs_event = True
        return reached

    def _c_do_step(self, t: float, h: float) -> int:
        """fmi3DoStep(t, h, noSetFMUStatePriorToCurrentPoint = true, ...): its status, the
        flags in ``self._flags``. The C function directly (looked up on the first call)."""
        raw = self.slave._slave
        fn = raw.dll["fmi3DoStep"]  # a private function object: our argtypes
        p_bool, p_double = ctypes.POINTER(ctypes.c_bool), ctypes.POINTER(ctypes.c_double)
        fn.argtypes = [ctypes.c_void_p, ctypes.c_double, ctypes.c_double, ctypes.c_bool,
                       p_bool, p_bool, p_bool, p_double]
        fn.restype = ctypes.c_int
        self._flags = (ctypes.c_bool(), ctypes.c_bool(), ctypes.c_bool(), ctypes.c_double())
        pointers = [ctypes.pointer(f) for f in self._flags]
        component = raw.component

        def do_step(t: float, h: float) -> int:
            return fn(component, t, h, True, *pointers)

        self._c_do_step = do_step  # type: ignore[method-assign]
        return do_step(t, h)

    # -- events --------------------------------------------------------------------------------
    def event_time(self) -> int | None:
        times = [t for t in (self._announced, *self._clock_next.values()) if t is not None]
        return min(times) if times else None

    def event_pending(self, ticks: int) -> bool:
        return (self._in_event or self._needs_event or self._announced == ticks
                or bool(self._triggered) or ticks in self._clock_next.values())

    def trigger(self, vr: int) -> None:
        """The triggered input clock ``vr`` ticks at this communication point (its source's
        output clock did): Event Mode entered if it is not yet (fmi3EnterEventMode, FMI 3.0
        sec. 4.2.1) and the clock activated (fmi3SetClock, sec. 2.2.8.4, in Event Mode: sec.
        2.3.5), before this FMU's inputs are set and fmi3UpdateDiscreteStates is called
        (:meth:`complete_event`)."""
        if not self._in_event:
            self.slave.enterEventMode()
            self._in_event = True
        self.slave.setClock([vr], [True])
        self._triggered.append(vr)

    def begin_event(self, ticks: int) -> None:
        if not self._in_event:
            self.slave.enterEventMode()
            self._in_event = True

    def complete_event(self, ticks: int) -> None:
        """Handle the event at ``ticks``: the input clocks due there set (fmi3SetClock; the
        triggered ones were, by :meth:`trigger`), fmi3UpdateDiscreteStates until no update is
        needed, then the intervals asked
        (:meth:`_asked_in_event`); a countdown or changing clock whose interval is 0 ticks at
        this event (FMI 3.0 sec. 2.2.8.2: T_interval,i >= 0): it is set and the discrete
        states updated again, until no clock ticks at interval 0."""
        now = self._seconds(ticks)
        ticking = [vr for vr, nxt in self._clock_next.items() if nxt == ticks]
        for _ in range(MAX_EVENT_ITERATIONS):
            if ticking:
                self.slave.setClock(ticking, [True] * len(ticking))
            defined, nxt = self._update_discrete_states(ticks)
            self._advance(ticking, ticks)
            ticking = self._ask_intervals(now, ticks, self._asked_in_event(ticking),
                                          zero_allowed=True)
            if not ticking:
                break
        else:
            raise SimulationError(f"{self.name}: at t = {to_seconds(ticks):g} s a countdown "
                                  f"or changing clock still ticks again at interval 0 after "
                                  f"{MAX_EVENT_ITERATIONS} ticks")
        self._announced = None
        self._triggered = []
        if defined:
            if not (math.isfinite(nxt) and nxt > now):
                raise SimulationError(f"{self.name}: nextEventTime = {nxt!r} s is not after the "
                                      f"current time {now!r} s (an FMU announcing "
                                      "its next event must give a later time)")
            self._announced = self._schedule(nxt, ticks)
        self.slave.enterStepMode()
        self._in_event = self._needs_event = False

    def _update_discrete_states(self, ticks: int) -> tuple[bool, float]:
        """fmi3UpdateDiscreteStates at the event at ``ticks`` until no update is needed (the
        watched output clocks asked before each call): (nextEventTimeDefined, nextEventTime)
        of the last call."""
        for _ in range(MAX_EVENT_ITERATIONS):
            self._read_output_clocks()
            update, terminate, _, _, defined, nxt = self.slave.updateDiscreteStates()
            if terminate:
                raise FmuTerminated(self, ticks)
            if not update:
                return defined, nxt
        raise SimulationError(f"{self.name}: fmi3UpdateDiscreteStates at t = "
                              f"{to_seconds(ticks):g} s still needs an update after "
                              f"{MAX_EVENT_ITERATIONS} calls (an event iteration that "
                              "does not converge)")

    def watch_clock(self, vr: int) -> None:
        """Ask the output clock ``vr`` at every event (it is wired to an input clock)."""
        if vr not in self.watched_clocks:
            self.watched_clocks.append(vr)

    def _read_output_clocks(self) -> None:
        """fmi3GetClock of the watched output clocks: those active join ``self.ticked``."""
        if self.watched_clocks:
            values = self.slave.getClock(self.watched_clocks)
            self.ticked += [vr for vr, on in zip(self.watched_clocks, values)
                            if on and vr not in self.ticked]

    def take_ticks(self) -> list[int]:
        """The watched output clocks that ticked at the last event (each handed out once)."""
        ticked, self.ticked = self.ticked, []
        return ticked

    def _advance(self, ticking: list[int], ticks: int) -> None:
        """Each clock of ``ticking`` ticked at ``ticks``: a periodic one ticks next one interval
        on, another when the FMU gives its interval."""
        for vr in ticking:
            self._clock_next[vr] = None
            if vr in self._clock_period:
                origin, period, k = self._clock_period[vr]
                self._clock_period[vr] = (origin, period, k + 1)
                self._clock_next[vr] = self._schedule(float(origin + (k + 1) * period), ticks)

    def _asked_in_event(self, ticked: list[int]) -> list[ClockAttributes]:
        """The input clocks whose intervals are asked in an Event Mode where the clocks
        ``ticked`` ticked (FMI 3.0 sec. 2.2.8.2): every countdown clock, every tunable one that
        declares no interval, and the changing ones that ticked."""
        return [c for c in self.input_clocks if c.interval_variability == "countdown"
                or (c.interval_variability == "tunable" and c.interval is None)
                or (c.interval_variability == "changing" and c.value_reference in ticked)]

    def _countdown_and_tunable(self) -> list[ClockAttributes]:
        """The countdown input clocks and the tunable ones that declare no interval."""
        return self._asked_in_event([])

    def _ask_intervals(self, now: float, ticks: int, asked: list[ClockAttributes],
                       zero_allowed: bool = False) -> list[int]:
        """Ask the intervals (fmi3GetIntervalDecimal) of the input clocks ``asked`` at the
        event at ``ticks`` (the FMU's time ``now``, s); a changed one schedules the clock's
        next tick (a countdown or changing clock that long after now, a tunable one that long
        after its last tick). ``zero_allowed``: a countdown or changing interval 0 means a
        tick now; those clocks are returned (else an interval must be positive)."""
        now_ticking = []
        for clock, (interval, qualifier) in zip(asked, self._intervals(asked) if asked else ()):
            if qualifier != fmi3IntervalChanged:
                continue
            vr = clock.value_reference
            aperiodic = clock.interval_variability in ("countdown", "changing")
            if aperiodic and zero_allowed and interval == 0:
                now_ticking.append(vr)
                continue
            if not interval > 0:
                raise SimulationError(f"{self.name}: {clock.interval_variability} clock "
                                      f"{clock.name} interval {float(interval)!r} s at t = "
                                      f"{now!r} s (must be positive)")
            if aperiodic:
                self._clock_next[vr] = self._schedule(float(Fraction(now) + interval), ticks)
            else:  # tunable: the next tick is the new interval after the last one
                origin, period, k = self._clock_period[vr]
                if k:
                    origin, k = origin + (k - 1) * period, 1
                self._clock_period[vr] = (origin, interval, k)
                self._clock_next[vr] = self._schedule(float(origin + k * interval), ticks)
        return now_ticking

    def _intervals(self, clocks: list[ClockAttributes]) -> list[tuple[Fraction, int]]:
        """fmi3GetIntervalDecimal of ``clocks`` (fmi3GetIntervalFraction of those that
        supportsFraction): (interval s, qualifier) each."""
        return [self._interval(c) for c in clocks]

    def _interval(self, clock: ClockAttributes) -> tuple[Fraction, int]:
        vr, qualifier = (ctypes.c_uint * 1)(clock.value_reference), (ctypes.c_int * 1)()
        if clock.supports_fraction:
            counter, resolution = (ctypes.c_uint64 * 1)(), (ctypes.c_uint64 * 1)()
            self.slave.getIntervalFraction(vr, counter, resolution, qualifier)
            if not resolution[0]:
                raise SimulationError(f"{self.name}: clock {clock.name}: "
                                      "fmi3GetIntervalFraction gave resolution 0")
            return Fraction(counter[0], resolution[0]), qualifier[0]
        interval = (ctypes.c_double * 1)()
        self.slave.getIntervalDecimal(vr, interval, qualifier)
        if not math.isfinite(interval[0]):
            return Fraction(0), qualifier[0]
        return Fraction(interval[0]), qualifier[0]

    def _shift(self, clock: ClockAttributes) -> Fraction:
        """fmi3GetShiftDecimal (fmi3GetShiftFraction when it supportsFraction) of ``clock``."""
        vr = (ctypes.c_uint * 1)(clock.value_reference)
        if clock.supports_fraction:
            counter, resolution = (ctypes.c_uint64 * 1)(), (ctypes.c_uint64 * 1)()
            self.slave.getShiftFraction(vr, counter, resolution)
            if not resolution[0]:
                raise SimulationError(f"{self.name}: clock {clock.name}: "
                                      "fmi3GetShiftFraction gave resolution 0")
            return Fraction(counter[0], resolution[0])
        shift = (ctypes.c_double * 1)()
        self.slave.getShiftDecimal(vr, shift)
        if not (math.isfinite(shift[0]) and shift[0] >= 0):
            raise SimulationError(f"{self.name}: clock {clock.name}: fmi3GetShiftDecimal gave "
                                  f"{shift[0]!r} s (must be >= 0)")
        return Fraction(shift[0])
