"""FMI 3.0 clock checks: the Clock variables and clocked variables of the modelDescription
(static, ``fmi3-clocks``), the calling sequence of a Scheduled Execution FMU
(``fmi3-scheduled-execution``, ``fmi3-scheduled-wrong-state``) and the clock functions of a
co-simulation FMU with clocks (``fmi3-clock-calls``). Every finding cites its FMI 3.0 clause.

Static (sec. 2.2.8.2 Clock Types, 2.4.4 attributes of ClockType, 2.4.7.4 Variable Attributes,
2.4.8 Model Structure, 4.4 hasEventMode): a Clock is a scalar, discrete input, output or local
variable; output and local Clocks are ``triggered``; ``priority`` is declared by every input
Clock of a Scheduled Execution FMU and by no output Clock; ``intervalDecimal`` is declared by
``constant`` Clocks and used by periodic Clocks only, ``shiftDecimal`` only with it;
``intervalCounter`` only for periodic Clocks with ``supportsFraction``, ``shiftCounter`` only
with it, ``resolution`` only for periodic Clocks; no local Clock in Scheduled Execution nor in
the ModelStructure; ``clocks`` lists value references of Clocks and only on discrete or tunable
variables; ``previous`` only on clocked discrete variables, referring to a distinct variable of
the same type that is discrete and no input; every ``ClockedState`` is a clocked discrete
non-Clock variable with ``previous``; ``canHandleMultipleSetPerTimeInstant`` only on inputs; a
co-simulation FMU with Clocks has Event Mode. The attribute values are read by the master's
reader (:func:`cosim.run.master.fmi3.clock_attributes`). Where the standard contradicts itself
nothing is reported: sec. 2.4.4 requires ``intervalDecimal`` of ``fixed`` and ``tunable``
Clocks, sec. 2.2.8.2 says how the importer proceeds when it is not defined.

Dynamic, Scheduled Execution (sec. 5.2): the FMU is instantiated for Scheduled Execution, the
intervals and shifts the modelDescription does not give are asked in Initialization Mode
(sec. 2.2.8.2), and in Clock Activation Mode every input Clock's model partition is activated
(fmi3ActivateModelPartition) at its ticks up to the default experiment's stop time (at most
``n_steps`` default steps): periodic Clocks at start + shift + k interval, ``changing`` ones
where fmi3GetInterval puts them after each tick, ``countdown`` ones where fmi3GetInterval puts
them after a clock-update callback (sec. 5.2.2; interval 0: at the same time, after the
partition that set it), ``triggered`` ones at every default communication point (the importer
chooses those). Simultaneous activations follow ``priority``. After a clock-update callback
the output Clocks are read (fmi3GetClock): an active one reads inactive on the next call (sec.
5.2.2). After each activation the variables of that partition are read, finite. Every call
returns fmi3OK or fmi3Warning (sec. 5.2: fmi3Discard counts as fmi3Error). A note lists the
activations. Wrong-state probes (what the importer must not do, an FMU should refuse it):
activation before initialisation, of a value reference that is no input Clock, of an output
Clock, twice at one time (sec. 5.2.1); fmi3SetClock (sec. 2.2.8.4).

Dynamic, co-simulation with Clocks and Event Mode (sec. 2.2.8.2 table): fmi3GetInterval /
fmi3GetShift in Initialization Mode as the Clock type requires, then a run whose steps end at
the input Clocks' ticks, where the Clocks are activated with fmi3SetClock in Event Mode; in
every Event Mode the ``countdown`` Clocks' intervals and, where they ticked, the ``changing``
ones' (interval 0: the Clock ticks again in the same Event Mode) and the output Clocks
(fmi3GetClock) are read. Every call returns fmi3OK or
fmi3Warning. A ``triggered`` input Clock is not activated: it ticks when the importer says,
from an output Clock of a connected FMU (sec. 2.2.8.2), which an FMU run alone has not; the
note says so.
"""

from __future__ import annotations

import ctypes
import math
from collections.abc import Callable
from fractions import Fraction
from pathlib import Path
from typing import Any
from xml.etree import ElementTree

from fmpy.fmi3 import (
    FMU3ScheduledExecution,
    fmi3ClockUpdateCallback,
    fmi3IntervalChanged,
    fmi3IntervalNotYetKnown,
)

from cosim.interop.compliance.common import NOTE, SKIPPED, Problem, _read_xml
from cosim.interop.compliance.fmi3 import _Host3, _Instance3
from cosim.run.master.errors import SimulationError
from cosim.run.master.fmi3 import (
    PERIODIC,
    ClockAttributes,
    clock_attributes,
    clock_types,
    declared_attributes,
    read_clock,
)

STATIC = "fmi3-clocks"
SCHEDULED = "fmi3-scheduled-execution"
SCHEDULED_WRONG_STATE = "fmi3-scheduled-wrong-state"
CLOCK_CALLS = "fmi3-clock-calls"

# FMI 3.0 clauses the findings cite
TYPES = "FMI 3.0 sec. 2.2.8.2, Clock Types"
PARTITIONS = "FMI 3.0 sec. 2.2.8.3, Model Partitions and Clocked Variables"
CLOCK_API = "FMI 3.0 sec. 2.2.8.4, Clocks specific API"
CLOCK_TYPE = "FMI 3.0 sec. 2.4.4, Variable Types: attributes of ClockType"
ARRAYS = "FMI 3.0 sec. 2.4.7.2, Array variables"
ATTRIBUTES = "FMI 3.0 sec. 2.4.7.4, Variable Attributes"
STRUCTURE = "FMI 3.0 sec. 2.4.8, Model Structure"
CS_SCHEMA = "FMI 3.0 sec. 4.4, Co-Simulation description schema: hasEventMode"
SE_MACHINE = "FMI 3.0 sec. 5.2, State Machine for Scheduled Execution"
ACTIVATION_MODE = "FMI 3.0 sec. 5.2.1, Clock Activation Mode"
UPDATE_MODE = "FMI 3.0 sec. 5.2.2, Clock Update Mode"

_CAUSALITIES = ("input", "output", "local")
_PARAMETERS = ("parameter", "calculatedParameter", "structuralParameter")
_FLOATS = ("Float32", "Float64")
_STATUS = {1: "fmi3Warning", 2: "fmi3Discard", 3: "fmi3Error", 4: "fmi3Fatal"}
_READABLE = ("Float64", "Float32", "Int8", "UInt8", "Int16", "UInt16", "Int32", "UInt32",
             "Int64", "UInt64", "Boolean")
MAX_ACTIVATIONS = 100_000  # activations of one run before the check gives up (a runaway FMU)


# -- static -------------------------------------------------------------------------------------
def _variability(var: ElementTree.Element) -> str:
    """The declared or default variability (FMI 3.0 sec. 2.4.7.4)."""
    if "variability" in var.attrib:
        return var.attrib["variability"]
    if var.get("causality", "local") in _PARAMETERS:
        return "fixed"
    return "continuous" if var.tag in _FLOATS else "discrete"


def clock_checks(path: Path) -> list[Problem]:
    """The static clock checks of an FMI 3.0 FMU (unclassified: see ``common.classify``)."""
    try:
        root = _read_xml(path)
    except Exception:
        return [Problem(STATIC, "not run: modelDescription.xml could not be read", SKIPPED)]
    node = root.find("ModelVariables")
    variables = list(node) if node is not None else []
    by_vr = {v.get("valueReference"): v for v in variables}
    types = clock_types(root)
    scheduled = root.find("ScheduledExecution") is not None
    problems: list[Problem] = []

    def bad(message: str, clause: str, check: str = STATIC) -> None:
        problems.append(Problem(check, f"{message} ({clause})"))

    clock_vrs = set()
    for var in variables:
        if var.tag == "Clock":
            clock_vrs.add(var.get("valueReference"))
            _clock_rules(path, var, declared_attributes(types, var), scheduled, bad)
    for var in variables:
        _clocked_rules(var, by_vr, clock_vrs, bad)
    previous = [v.get("previous") for v in variables if v.get("previous") is not None]
    for vr in sorted({p for p in previous if previous.count(p) > 1}):
        bad(f"two variables have previous = {vr}", ATTRIBUTES)
    structure = root.find("ModelStructure")
    for element in structure if structure is not None else []:
        var = by_vr.get(element.get("valueReference"))
        if var is None:
            continue
        name = var.get("name")
        if var.tag == "Clock" and var.get("causality", "local") == "local":
            bad(f"local Clock {name} is listed in ModelStructure as {element.tag}; local Clocks "
                "must not be listed there", TYPES)
        if element.tag == "ClockedState" and (
                var.tag == "Clock" or var.get("previous") is None or not var.get("clocks")
                or _variability(var) != "discrete"):
            bad(f"ClockedState {name}: a clocked state is a discrete variable with the "
                "attributes clocks and previous, not a Clock", STRUCTURE)
    cs = root.find("CoSimulation")
    if clock_vrs and cs is not None and cs.get("hasEventMode", "false") != "true":
        bad("the FMU has Clocks, so CoSimulation hasEventMode must be true", CS_SCHEMA)
    return problems


def _clock_rules(path: Path, var: ElementTree.Element, a: dict[str, str], scheduled: bool,
                 bad: Callable[[str, str], None]) -> None:
    """The rules of one Clock variable ``var`` with attributes ``a`` (its declared type's
    attributes overridden by its own)."""
    name = a.get("name", "?")
    causality = a.get("causality", "local")
    kind = a.get("intervalVariability")
    try:
        read_clock(path, a)  # the values: numbers in range, a known intervalVariability
    except SimulationError as err:
        bad(str(err), f"{CLOCK_TYPE}; {TYPES}")
    if causality not in _CAUSALITIES:
        bad(f"Clock {name}: causality {causality!r}; a Clock is an input, output or local",
            ATTRIBUTES)
    if _variability(var) != "discrete":
        bad(f"Clock {name}: variability {_variability(var)!r}; a Clock is discrete", ATTRIBUTES)
    if var.find("Dimension") is not None:
        bad(f"Clock {name} has a Dimension; Clocks are scalar", f"{TYPES}; {ARRAYS}")
    if causality in ("output", "local") and kind != "triggered":
        bad(f"{causality} Clock {name}: intervalVariability {kind!r}; {causality} Clocks are "
            "triggered", TYPES)
    if causality == "output" and "priority" in a:
        bad(f"output Clock {name} declares a priority; output Clocks must not", CLOCK_TYPE)
    if scheduled and causality == "input" and "priority" not in a:
        bad(f"input Clock {name} has no priority, which every input Clock of a Scheduled "
            "Execution FMU declares", CLOCK_TYPE)
    if scheduled and causality == "local":
        bad(f"local Clock {name}: local Clocks are not allowed in Scheduled Execution", TYPES)
    periodic = kind in PERIODIC
    fraction = a.get("supportsFraction", "false") == "true"
    for key, allowed, why in (
            ("intervalDecimal", periodic, "is used by periodic (constant, fixed, tunable) "
                                          "Clocks only"),
            ("shiftDecimal", "intervalDecimal" in a, "requires intervalDecimal"),
            ("intervalCounter", periodic and fraction, "is used by periodic Clocks with "
                                                       "supportsFraction = true only"),
            ("shiftCounter", "intervalCounter" in a, "requires intervalCounter"),
            ("resolution", periodic, "is used by periodic Clocks only")):
        if key in a and not allowed:
            bad(f"Clock {name} ({kind}): {key} = {a[key]!r}, which {why}", CLOCK_TYPE)
    if kind == "constant" and "intervalDecimal" not in a and "intervalCounter" in a:
        bad(f"constant Clock {name} declares intervalCounter but no intervalDecimal, which a "
            "constant Clock declares", f"{TYPES}; {CLOCK_TYPE}")
    for key in ("intermediateUpdate", "previous"):
        if key in var.attrib:
            bad(f"Clock {name} has the attribute {key}, which Clocks must not have",
                ATTRIBUTES)


def _clocked_rules(var: ElementTree.Element, by_vr: dict[str | None, ElementTree.Element],
                   clock_vrs: set[str | None], bad: Callable[..., None]) -> None:
    """The ``clocks``, ``previous`` and ``canHandleMultipleSetPerTimeInstant`` rules of one
    variable."""
    name = var.get("name")
    clocks = var.get("clocks")
    if clocks is not None:
        references = clocks.split()
        if not references:
            bad(f"{name}: clocks is empty; it lists the value references of Clocks",
                ATTRIBUTES)
        for vr in references:
            if vr not in clock_vrs:
                what = ("no variable" if vr not in by_vr
                        else f"{by_vr[vr].tag} {by_vr[vr].get('name')}, not a Clock")
                bad(f"{name}: clocks lists {vr!r}, which is {what}", f"{ATTRIBUTES}; "
                    f"{PARTITIONS}")
        if _variability(var) not in ("discrete", "tunable"):
            bad(f"{name}: clocked (clocks = {clocks!r}) with variability "
                f"{_variability(var)!r}; a clocked variable is discrete or tunable",
                ATTRIBUTES)
    previous = var.get("previous")
    if previous is not None and var.tag != "Clock":
        other = by_vr.get(previous)
        if clocks is None or _variability(var) != "discrete":
            bad(f"{name}: previous = {previous}, but only clocked discrete variables have "
                "previous", ATTRIBUTES)
        if other is None or other is var:
            bad(f"{name}: previous = {previous} refers to "
                f"{'itself' if other is var else 'no variable'}", ATTRIBUTES)
        elif (other.tag != var.tag or _variability(other) != "discrete"
              or other.get("causality") == "input"):
            bad(f"{name}: previous = {previous} refers to {other.tag} {other.get('name')}, "
                f"which must be a discrete {var.tag} and no input", ATTRIBUTES)
    if ("canHandleMultipleSetPerTimeInstant" in var.attrib
            and var.get("causality", "local") != "input"):
        bad(f"{name}: canHandleMultipleSetPerTimeInstant on a {var.get('causality', 'local')} "
            "variable; the attribute is only for inputs", ATTRIBUTES, "fmi3-variables")


# -- dynamic: shared ----------------------------------------------------------------------------
class _ClockedScheduledExecution(FMU3ScheduledExecution):
    """fmpy's Scheduled Execution FMU, instantiated with a clock-update callback that counts
    the FMU's calls (fmpy passes one that does nothing)."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self.clock_updates = 0
        self._on_update = fmi3ClockUpdateCallback(self._count)
        native = self.fmi3InstantiateScheduledExecution

        def instantiate(*args: Any) -> Any:  # the 8th argument is the clock-update callback
            return native(*args[:7], self._on_update, *args[8:])

        self.fmi3InstantiateScheduledExecution = instantiate  # type: ignore[method-assign]

    def _count(self, environment: Any) -> None:
        self.clock_updates += 1


class _ScheduledInstance(_Instance3):
    """One FMI 3 Scheduled Execution instance (Clock Activation Mode after initialisation)."""

    INSTANTIATE = "fmi3InstantiateScheduledExecution"

    @staticmethod
    def _fmpy_class() -> type:
        return _ClockedScheduledExecution

    def _instantiate(self, log: Callable[..., None], **kw: Any) -> None:
        self.fmu.instantiate(loggingOn=False, logMessage=log)


def _said(inst: _Instance3) -> str:
    said = " | ".join(m for _, m in inst.messages[-2:]).strip()
    return f"; FMU says: {said}" if said else ""


class _Run:
    """Findings of one dynamic run: ``ok`` checks a status, ``fail`` records a finding."""

    def __init__(self, check: str, inst: _Instance3) -> None:
        self.check, self.inst = check, inst
        self.problems: list[Problem] = []

    def fail(self, message: str, clause: str) -> None:
        self.problems.append(Problem(self.check, f"{message} ({clause})"))

    def ok(self, status: int, call: str, clause: str, discard_is_error: bool = False) -> bool:
        """True when ``status`` is fmi3OK / fmi3Warning (and fmi3Discard unless
        ``discard_is_error``)."""
        if status <= 1 or status == 2 and not discard_is_error:
            return True
        self.fail(f"{call} returned {_STATUS.get(status, status)}{_said(self.inst)}", clause)
        return False


def _interval(run: _Run, clock: ClockAttributes, where: str, clause: str
              ) -> tuple[Fraction | None, int]:
    """fmi3GetIntervalDecimal of ``clock``: (interval s or None when the call failed or gave
    no finite value, qualifier)."""
    vr, qualifier = (ctypes.c_uint32 * 1)(clock.value_reference), (ctypes.c_int * 1)()
    value = (ctypes.c_double * 1)()
    status, _ = run.inst.call("getIntervalDecimal", vr, value, qualifier)
    if not run.ok(status, f"fmi3GetIntervalDecimal({clock.name}) in {where}", clause, True):
        return None, -1
    if qualifier[0] == fmi3IntervalNotYetKnown and clock.interval_variability != "countdown":
        run.fail(f"fmi3GetIntervalDecimal({clock.name}) in {where} answered "
                 f"fmi3IntervalNotYetKnown, which only a countdown Clock may answer", CLOCK_API)
    periodic = clock.interval_variability in PERIODIC
    if qualifier[0] == fmi3IntervalNotYetKnown or (
            not periodic and qualifier[0] != fmi3IntervalChanged):
        return None, qualifier[0]  # a periodic Clock's interval holds whatever the qualifier
    if not (math.isfinite(value[0]) and value[0] >= 0) or periodic and not value[0] > 0:
        run.fail(f"fmi3GetIntervalDecimal({clock.name}) in {where} gave the interval "
                 f"{value[0]!r} s", TYPES)
        return None, qualifier[0]
    return Fraction(value[0]), qualifier[0]


def _initial_schedule(run: _Run, clocks: list[ClockAttributes], start: Fraction
                      ) -> tuple[dict[int, Fraction | None], dict[int, tuple[Fraction, Fraction]]]:
    """In Initialization Mode: the first tick of each time-based input Clock (None: not yet
    known) and (first tick, interval) of each periodic one; intervals and shifts the
    modelDescription does not declare are asked of the FMU (sec. 2.2.8.2)."""
    following: dict[int, Fraction | None] = {}
    periods: dict[int, tuple[Fraction, Fraction]] = {}
    where = "Initialization Mode"
    for clock in clocks:
        kind, vr = clock.interval_variability, clock.value_reference
        if kind == "triggered":
            continue
        if kind in PERIODIC and clock.interval is not None:
            interval, shift = clock.interval, clock.shift or Fraction(0)
        else:
            interval, qualifier = _interval(run, clock, where, TYPES)
            shift = Fraction(0)
            if kind in PERIODIC:
                value = (ctypes.c_double * 1)()
                status, _ = run.inst.call("getShiftDecimal", (ctypes.c_uint32 * 1)(vr), value)
                if run.ok(status, f"fmi3GetShiftDecimal({clock.name}) in {where}", TYPES, True):
                    if not (math.isfinite(value[0]) and value[0] >= 0):
                        run.fail(f"fmi3GetShiftDecimal({clock.name}) gave {value[0]!r} s",
                                 CLOCK_TYPE)
                    else:
                        shift = Fraction(value[0])
        if interval is None:
            following[vr] = None
        elif kind in PERIODIC:  # t0 = start + shift, then every interval
            following[vr] = start + shift
            periods[vr] = (start + shift, interval)
        else:  # changing, countdown: t0 = start + interval
            following[vr] = start + interval
    return following, periods


def _times(times: list[float]) -> str:
    shown = ", ".join(f"{t:g}" for t in times[:12])
    return shown + (f", ... {times[-1]:g}" if len(times) > 12 else "")


def _clocks(host: _Host3, check: str) -> dict[int, ClockAttributes] | list[Problem]:
    """The FMU's Clocks, or the finding that they cannot be read."""
    try:
        return clock_attributes(host.path)
    except SimulationError as err:
        return [Problem(check, f"not run: the Clocks cannot be read: {err} (see {STATIC})",
                        SKIPPED)]


def _clocked_reads(host: _Host3) -> dict[int | None, list[Any]]:
    """Clock value reference (None: no clock) -> the scalar output variables it clocks."""
    out: dict[int | None, list[Any]] = {}
    for v in host.md.modelVariables:
        if v.causality != "output" or v.type not in _READABLE or v.dimensions:
            continue
        for clock in v.clocks or [None]:
            out.setdefault(None if clock is None else clock.valueReference, []).append(v)
    return out


def _read(run: _Run, variables: list[Any], when: str, clause: str) -> None:
    for v in variables:
        status, values = run.inst.call(f"get{v.type}", [v.valueReference])
        if run.ok(status, f"fmi3Get{v.type}({v.name}) {when}", clause, True) and (
                v.type in _FLOATS and not math.isfinite(values[0])):
            run.fail(f"{v.name} is {values[0]} {when}", clause)


# -- dynamic: Scheduled Execution ---------------------------------------------------------------
def _check_scheduled_execution(host: _Host3, ctx: dict) -> list[Problem]:
    if host.se is None:
        return [Problem(SCHEDULED, "not applicable: no ScheduledExecution interface", NOTE)]
    clocks = _clocks(host, SCHEDULED)
    if isinstance(clocks, list):
        return clocks
    inputs = [c for c in clocks.values() if c.causality == "input"]
    outputs = [c for c in clocks.values() if c.causality == "output"]
    reads = _clocked_reads(host)
    inst = _ScheduledInstance(host, "scheduled")
    run = _Run(SCHEDULED, inst)
    start = Fraction(host.start)
    stop = start + host.n * Fraction(host.h)
    if not run.ok(inst.call("enterInitializationMode", startTime=host.start)[0],
                  "fmi3EnterInitializationMode", SE_MACHINE, True):
        inst.free()
        return run.problems
    following, periods = _initial_schedule(run, inputs, start)
    if run.problems or not run.ok(inst.call("exitInitializationMode")[0],
                                  "fmi3ExitInitializationMode", SE_MACHINE, True):
        inst.free()
        return run.problems
    by_vr = {c.value_reference: c for c in inputs}
    order = {c.value_reference: (c.priority if c.priority is not None else math.inf,
                                 c.value_reference) for c in inputs}
    triggered = [c.value_reference for c in inputs if c.interval_variability == "triggered"]
    ticks = {c.value_reference: 0 for c in inputs}  # ticks of each periodic clock so far
    activations: dict[str, list[float]] = {c.name: [] for c in inputs}
    output_ticks: dict[str, int] = {c.name: 0 for c in outputs}
    fmu = inst.fmu
    k, count = 0, 0  # next communication point of the triggered clocks, activations so far
    while count < MAX_ACTIVATIONS:
        pending = [t for t in following.values() if t is not None]
        trigger_time = start + k * Fraction(host.h) if triggered else None
        now = min(pending + ([trigger_time] if trigger_time is not None else []), default=None)
        if now is None or now >= stop:
            break
        due = {vr for vr, t in following.items() if t == now}
        if trigger_time == now:
            due |= set(triggered)
            k += 1
        done: set[int] = set()
        while due and count < MAX_ACTIVATIONS:
            vr = min(due, key=order.__getitem__)
            due.discard(vr)
            clock = by_vr[vr]
            updates = fmu.clock_updates
            call = f"fmi3ActivateModelPartition({clock.name}, {float(now)!r})"
            if not run.ok(inst.call("activateModelPartition", vr, float(now))[0], call,
                          SE_MACHINE, True):
                inst.free()
                return run.problems
            done.add(vr)
            count += 1
            activations[clock.name].append(float(now))
            if vr in periods:
                ticks[vr] += 1
                first, interval = periods[vr]
                following[vr] = first + ticks[vr] * interval
            elif clock.interval_variability == "changing":
                interval, _ = _interval(run, clock, f"Clock Activation Mode at {float(now)!r}",
                                        TYPES)
                following[vr] = None if interval is None else now + interval
            elif following.get(vr) == now:
                following[vr] = None  # a countdown Clock ticks again when the FMU says so
            _read(run, reads.get(vr, []), f"after {call}", ACTIVATION_MODE)
            if fmu.clock_updates == updates:
                continue
            for out in outputs:  # Clock Update Mode: which output Clocks ticked
                status, value = inst.call("getClock", [out.value_reference])
                if not run.ok(status, f"fmi3GetClock({out.name}) in Clock Update Mode",
                              UPDATE_MODE, True):
                    continue
                if value[0]:
                    output_ticks[out.name] += 1
                    status, again = inst.call("getClock", [out.value_reference])
                    if status <= 1 and again[0]:
                        run.fail(f"output Clock {out.name} reads active twice for one "
                                 "activation", UPDATE_MODE)
            for countdown in (c for c in inputs if c.interval_variability == "countdown"):
                interval, _ = _interval(run, countdown, "Clock Update Mode", UPDATE_MODE)
                if interval is None:
                    continue
                cvr = countdown.value_reference
                if interval == 0 and cvr in done:
                    run.fail(f"countdown Clock {countdown.name} was given interval 0 at "
                             f"{float(now)!r} s after its partition ran at that time; "
                             "fmi3ActivateModelPartition is called once per Clock and time",
                             ACTIVATION_MODE)
                elif interval == 0:
                    due.add(cvr)
                else:
                    following[cvr] = now + interval
        _read(run, reads.get(None, []), f"at {float(now)!r} s", ACTIVATION_MODE)
    if count >= MAX_ACTIVATIONS:
        run.fail(f"more than {MAX_ACTIVATIONS} activations before {float(stop)!r} s",
                 ACTIVATION_MODE)
    run.ok(inst.call("terminate")[0], "fmi3Terminate", SE_MACHINE, True)
    errors = [m for s, m in inst.messages if s >= 3]
    inst.free()
    if errors:
        run.fail(f"error messages in a nominal run: {errors[0]}", SE_MACHINE)
    summary = "; ".join(f"{name} at {_times(ts)} s" if ts else f"{name} never"
                        for name, ts in activations.items())
    ticked = "; ".join(f"{name} {n} times" for name, n in output_ticks.items())
    run.problems.append(Problem(SCHEDULED, f"activations up to {float(stop):g} s: {summary}"
                                + (f"; output Clocks ticked: {ticked}" if ticked else ""),
                                NOTE))
    return run.problems


def _check_scheduled_wrong_state(host: _Host3, ctx: dict) -> list[Problem]:
    """Calls an importer must not make; an FMU should refuse them (not fmi3OK)."""
    if host.se is None:
        return [Problem(SCHEDULED_WRONG_STATE, "not applicable: no ScheduledExecution "
                                               "interface", NOTE)]
    clocks = _clocks(host, SCHEDULED_WRONG_STATE)
    if isinstance(clocks, list):
        return clocks
    inputs = sorted((c for c in clocks.values() if c.causality == "input"),
                    key=lambda c: c.value_reference)
    outputs = [c for c in clocks.values() if c.causality == "output"]
    if not inputs:
        return []
    clock, t = inputs[0], host.start
    problems: list[Problem] = []

    def refused(status: int, call: str, clause: str) -> None:
        if status == 0:
            problems.append(Problem(SCHEDULED_WRONG_STATE, f"{call} returned fmi3OK ({clause})"))

    inst = _ScheduledInstance(host, "wrong-state")
    refused(inst.call("activateModelPartition", clock.value_reference, t)[0],
            f"fmi3ActivateModelPartition({clock.name}) before initialisation", SE_MACHINE)
    inst.free()
    inst = _ScheduledInstance(host, "wrong-state2")
    inst.init()  # Clock Activation Mode
    unknown = 1 + max(v.valueReference for v in host.md.modelVariables)
    refused(inst.call("activateModelPartition", unknown, t)[0],
            f"fmi3ActivateModelPartition of value reference {unknown} (no variable)",
            ACTIVATION_MODE)
    for out in outputs:
        refused(inst.call("activateModelPartition", out.value_reference, t)[0],
                f"fmi3ActivateModelPartition of the output Clock {out.name}", ACTIVATION_MODE)
    refused(inst.call("setClock", [clock.value_reference], [True])[0],
            f"fmi3SetClock({clock.name}) in Scheduled Execution", CLOCK_API)
    if inst.call("activateModelPartition", clock.value_reference, t)[0] <= 1:
        refused(inst.call("activateModelPartition", clock.value_reference, t)[0],
                f"a second fmi3ActivateModelPartition({clock.name}, {t!r}) at the same time",
                ACTIVATION_MODE)
    inst.free()
    return problems


# -- dynamic: co-simulation with clocks ---------------------------------------------------------
def _check_clock_calls(host: _Host3, ctx: dict) -> list[Problem]:
    """A co-simulation run with Event Mode whose input Clocks tick (fmi3SetClock) and whose
    countdown intervals and output Clocks are read in every Event Mode."""
    if host.cs is None or not any(v.type == "Clock" for v in host.md.modelVariables):
        return [Problem(CLOCK_CALLS, "not applicable: no co-simulation interface with Clocks",
                        NOTE)]
    if not host.has_event_mode:
        return [Problem(CLOCK_CALLS, "not run: the FMU has Clocks but no Event Mode (see "
                                     f"{STATIC})", NOTE)]
    clocks = _clocks(host, CLOCK_CALLS)
    if isinstance(clocks, list):
        return clocks
    inputs = [c for c in clocks.values() if c.causality == "input"]
    outputs = [c for c in clocks.values() if c.causality == "output"]
    countdowns = [c for c in inputs if c.interval_variability == "countdown"]
    inst = host.instance("clocks", eventModeUsed=True)
    run = _Run(CLOCK_CALLS, inst)
    start = Fraction(host.start)
    stop = start + host.n * Fraction(host.h)
    inst.must("enterInitializationMode", startTime=host.start)
    following, periods = _initial_schedule(run, inputs, start)
    ticks = {vr: 0 for vr in periods}
    inst.must("exitInitializationMode")  # Event Mode (eventModeUsed)
    activations: dict[str, list[float]] = {c.name: [] for c in inputs}
    by_vr = {c.value_reference: c for c in inputs}
    now, terminate, count = start, False, 0

    def event_mode(due: set[int]) -> tuple[bool, float | None]:
        """The Event Mode at ``now`` with the Clocks ``due`` ticking; a countdown or changing
        Clock given interval 0 ticks again in it, until none is."""
        nonlocal count
        while True:
            for vr in due:
                activations[by_vr[vr].name].append(float(now))
                count += 1
                if vr in periods:
                    ticks[vr] += 1
                    following[vr] = periods[vr][0] + ticks[vr] * periods[vr][1]
                else:
                    following[vr] = None
            if due:
                vrs = sorted(due)
                run.ok(inst.call("setClock", vrs, [True] * len(vrs))[0],
                       f"fmi3SetClock({', '.join(by_vr[vr].name for vr in vrs)}) in Event "
                       "Mode", TYPES)
            result = inst.event_mode(run.problems)
            # countdown Clocks: in every Event Mode; changing ones: when they ticked
            for c in countdowns + [by_vr[vr] for vr in due
                                   if by_vr[vr].interval_variability == "changing"]:
                interval, _ = _interval(run, c, f"Event Mode at {float(now)!r} s", TYPES)
                if interval is not None:
                    following[c.value_reference] = now + interval
            for out in outputs:
                run.ok(inst.call("getClock", [out.value_reference])[0],
                       f"fmi3GetClock({out.name}) in Event Mode", TYPES)
            due = {c.value_reference for c in inputs
                   if c.interval_variability in ("countdown", "changing")
                   and following[c.value_reference] == now}
            if not due or result[0] or count >= MAX_ACTIVATIONS:
                return result

    terminate, next_event = event_mode({vr for vr, t in following.items() if t == now})
    in_event = True  # Event Mode; a step without an event stays in Step Mode (sec. 4.2)
    while now < stop and not terminate and count < MAX_ACTIVATIONS and not run.problems:
        due_times = [t for t in following.values() if t is not None and t > now]
        if next_event is not None and Fraction(next_event) > now:
            due_times.append(Fraction(next_event))
        end = min([now + Fraction(host.h), stop, *due_times])
        if in_event:
            inst.must("enterStepMode")
            in_event = False
        event, terminate, _, _ = inst.must("doStep", currentCommunicationPoint=float(now),
                                           communicationStepSize=float(end - now))
        now = end
        due = {vr for vr, t in following.items() if t == now}
        if terminate or not (due or event or next_event is not None
                             and abs(float(now) - next_event) <= 1e-9 * max(1.0, float(now))):
            continue
        inst.must("enterEventMode")
        in_event = True
        terminate, next_event = event_mode(due)
    errors = [m for s, m in inst.messages if s >= 3]
    if not terminate:
        inst.must("terminate")
    inst.free()
    if errors:
        run.fail(f"error messages in a run with Clocks: {errors[0]}", TYPES)
    triggered = {c.name for c in inputs if c.interval_variability == "triggered"}
    summary = "; ".join(f"{name} at {_times(ts)} s" if ts else
                        f"{name} not exercised (a triggered Clock ticks when an output Clock "
                        f"of a connected FMU does, {TYPES}: an FMU run alone has none)"
                        if name in triggered else f"{name} never"
                        for name, ts in activations.items())
    if summary:
        run.problems.append(Problem(CLOCK_CALLS, f"input Clocks activated up to "
                                                 f"{float(stop):g} s: {summary}", NOTE))
    return run.problems


DYNAMIC = {
    CLOCK_CALLS: _check_clock_calls,
    SCHEDULED: _check_scheduled_execution,
    SCHEDULED_WRONG_STATE: _check_scheduled_wrong_state,
}
