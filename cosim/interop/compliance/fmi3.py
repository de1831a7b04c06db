"""FMI 3.0 co-simulation compliance checks (any FMI 3.0 FMU: ours from ``cosim build --fmi 3``
or a third party's). :func:`cosim.interop.compliance.check_fmu` runs them on an FMU whose
modelDescription says ``fmiVersion="3.0"``.

Static (read from the file): fmpy's FMI 3.0 schema and rule validation; variables
(causality/variability/initial combinations, start values where required, inside min/max,
units declared, exactly one independent variable); model structure (every output listed
as ``ModelStructure/Output``, dependencies naming variables that exist); capabilities (a
``CoSimulation`` or ``ScheduledExecution`` element, a binary for this platform). The checks of
Clocks and Scheduled Execution are in :mod:`cosim.interop.compliance.clocks`; the co-simulation
checks below note themselves not applicable to an FMU without a ``CoSimulation`` element.

Dynamic (the FMU is loaded and run in the compliance worker subprocess, see
:mod:`cosim.interop.compliance.worker`): the calling sequence without Event Mode
(instantiate -> fmi3EnterInitializationMode -> fmi3ExitInitializationMode -> fmi3DoStep* ->
fmi3Terminate -> fmi3FreeInstance, no early return when it was not allowed); Event Mode for an
FMU declaring ``hasEventMode`` (Event Mode after initialisation, fmi3UpdateDiscreteStates
converging, ``nextEventTime`` not in the past, each step ending at the announced event,
``eventHandlingNeeded`` answered by Event Mode); early return (only when allowed and declared by
``mightReturnEarlyFromDoStep``, ``lastSuccessfulTime`` inside the step); FMU state (get/set and
serialise reproduce the rest of the run exactly, when declared); calls outside the state
machine are detected. Inputs follow the deterministic signal of the FMI 2 checks; every Float64
input inside [min, max].
"""

from __future__ import annotations

import math
import platform
import zipfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from cosim.interop.compliance.common import (
    CONVENTION,
    FMI3_STATIC_CHECKS,
    RECOMMENDED,
    WARNING,
    Problem,
    _num,
    _read_xml,
    skipped,
)
from cosim.interop.compliance.host import WATCHDOG, _differs, _matching, _out_name, describe_call
from cosim.run.master.fmi3 import read_model_description, resolved_description

# FMI 3.0 sec. 2.4.7.4 (Variable Attributes): legal causality for each variability
_LEGAL = {
    "constant": {"output", "local"},
    "fixed": {"parameter", "calculatedParameter", "structuralParameter", "local"},
    "tunable": {"parameter", "calculatedParameter", "structuralParameter", "local"},
    "discrete": {"input", "output", "local"},
    "continuous": {"input", "output", "local", "independent"},
}
_FLOAT = ("Float32", "Float64")
_PLATFORM = {"x86_64": "x86_64", "AMD64": "x86_64", "aarch64": "aarch64"}.get(
    platform.machine(), platform.machine()) + "-" + {"darwin": "darwin", "win32": "windows"}.get(
    __import__("sys").platform, "linux")


def _binary_ok(path: Path, identifier: str | None) -> bool:
    ext = {"linux": ".so", "darwin": ".dylib", "windows": ".dll"}[_PLATFORM.split("-")[1]]
    with zipfile.ZipFile(path) as z:
        return f"binaries/{_PLATFORM}/{identifier}{ext}" in z.namelist()


def static_checks(path: Path) -> list[Problem]:
    """The static FMI 3.0 checks (unclassified: see ``common.classify``)."""
    from fmpy.validation import validate_fmu

    problems: list[Problem] = []
    try:  # with ClockTypes: fmpy validates the description alone (no file-path checks)
        messages = validate_fmu(resolved_description(path) or str(path))
        root = _read_xml(path)
    except Exception as err:
        return skipped(tuple(c for c in FMI3_STATIC_CHECKS if c != "fmi3-clocks"),
                       "the archive could not be read",
                       [Problem("fmi3-validation", f"cannot be validated: {err}")])
    problems += [Problem("fmi3-validation", str(m).strip()) for m in messages]
    variables = root.find("ModelVariables")
    xml_vars = list(variables) if variables is not None else []
    declared_units = {u.get("name") for u in root.iter("Unit")}
    independents = []
    by_vr: dict[str, Any] = {}
    for var in xml_vars:
        name, kind = var.get("name"), var.tag
        by_vr[var.get("valueReference")] = var
        causality = var.get("causality", "local")
        variability = var.get("variability", "continuous" if kind in _FLOAT else "discrete")
        initial = var.get("initial")
        if causality == "independent":
            independents.append(name)
            if kind not in _FLOAT or var.get("start") is not None or initial is not None:
                problems.append(Problem("fmi3-variables", f"{name}: the independent variable "
                                        "must be a float without start or initial (2.4)"))
        if variability not in _LEGAL:
            problems.append(Problem("fmi3-variables", f"{name}: unknown variability "
                                                      f"{variability!r}"))
            continue
        if causality not in _LEGAL[variability]:
            problems.append(Problem("fmi3-variables", f"{name}: causality {causality!r} with "
                                    f"variability {variability!r} is not allowed (2.4)"))
        if kind not in _FLOAT and variability == "continuous":
            problems.append(Problem("fmi3-variables", f"{name}: a {kind} cannot be continuous"))
        start = var.get("start")
        if kind in ("String", "Binary"):
            starts = var.findall("Start")
            start = starts[0].get("value") if starts else start
        if (causality in ("parameter", "input", "structuralParameter") and start is None
                and kind != "Clock"):  # a clock has no start value (2.4)
            problems.append(Problem("fmi3-variables", f"{name}: a start value is required "
                                                      f"({causality}, 2.4)"))
        if initial == "calculated" and start is not None:
            problems.append(Problem("fmi3-variables", f"{name}: initial=calculated with a "
                                                      "start value (2.4)"))
        lo, hi = _num(var.get("min")), _num(var.get("max"))
        values = [_num(s) for s in (start or "").split()] if kind not in ("String",
                                                                          "Binary") else []
        if lo is not None and hi is not None and lo > hi:
            problems.append(Problem("fmi3-variables", f"{name}: min {lo} > max {hi}"))
        for st in values:
            if st is not None and (lo is not None and st < lo or hi is not None and st > hi):
                problems.append(Problem("fmi3-variables", f"{name}: start {st} outside "
                                                          f"[{lo}, {hi}]"))
        unit = var.get("unit")
        if unit and declared_units and unit not in declared_units:
            problems.append(Problem("fmi3-variables", f"{name}: unit {unit!r} is not declared "
                                                      "in UnitDefinitions (2.4)"))
        if kind in _FLOAT and not unit and not var.get("declaredType") and causality in (
                "input", "output", "parameter"):
            problems.append(Problem("fmi3-variables", f"{name}: float variable without a unit",
                                    requirement=CONVENTION))
    if len(independents) != 1:
        problems.append(Problem("fmi3-variables", f"{len(independents)} independent variables "
                                "(exactly one is required, 2.4)"))
    # model structure
    structure = root.find("ModelStructure")
    listed = {}
    for node in structure.findall("Output") if structure is not None else []:
        listed[node.get("valueReference")] = node
        for dep in (node.get("dependencies") or "").split():
            if dep not in by_vr:
                problems.append(Problem("fmi3-model-structure", f"Output "
                                        f"{node.get('valueReference')}: dependency {dep} is no "
                                        "variable's value reference"))
        if node.get("dependencies") is None:
            problems.append(Problem("fmi3-model-structure", f"output "
                                    f"{by_vr.get(node.get('valueReference'), node).get('name')}"
                                    ": no explicit dependencies attribute (it then depends on "
                                    "every input)", requirement=CONVENTION))
    for vr, var in by_vr.items():
        if var.get("causality") == "output" and vr not in listed:
            problems.append(Problem("fmi3-model-structure", f"output {var.get('name')} is not "
                                    "listed in ModelStructure as Output"))
    # the interface the dynamic checks load: co-simulation, else Scheduled Execution
    interface = root.find("CoSimulation")
    if interface is None:
        interface = root.find("ScheduledExecution")
    if interface is None:
        problems.append(Problem("fmi3-capabilities", "neither a co-simulation nor a Scheduled "
                                "Execution FMU (no CoSimulation or ScheduledExecution "
                                "element): these checks are for those interfaces",
                                requirement=CONVENTION))
    elif not _binary_ok(path, interface.get("modelIdentifier")):
        problems.append(Problem("fmi3-capabilities", f"no binary for this platform "
                                f"(binaries/{_PLATFORM}/{interface.get('modelIdentifier')}.*): "
                                "the dynamic checks cannot run here", WARNING))
    return problems


# -- dynamic checks (run in the worker) ----------------------------------------------------------
class _Host3:
    """One FMI 3.0 FMU loaded for the dynamic checks."""

    def __init__(self, path: Path, unzipdir: str, n_steps: int,
                 irreproducible: tuple[str, ...] = ()) -> None:
        self.path, self.unzipdir = path, unzipdir
        self.md = read_model_description(path, validate=False)
        self.cs = self.md.coSimulation  # None: no co-simulation interface
        self.se = self.md.scheduledExecution  # None: no Scheduled Execution interface
        self.model_identifier = (self.cs or self.se).modelIdentifier
        variables = self.md.modelVariables
        self.inputs = [v for v in variables if v.causality == "input" and v.type == "Float64"
                       and not v.dimensions]
        self.outputs = [v for v in variables if v.causality == "output" and not v.dimensions
                        and v.type in ("Float64", "Float32", "Int32", "Int8", "UInt8", "Int16",
                                       "UInt16", "UInt32", "Int64", "UInt64", "Boolean",
                                       "Enumeration")]
        self.irreproducible = _matching(self.outputs, irreproducible)
        de = self.md.defaultExperiment
        self.start = float(de.startTime) if de is not None and de.startTime is not None else 0.0
        stop = float(de.stopTime) if de is not None and de.stopTime is not None else None
        step = float(de.stepSize) if de is not None and de.stepSize is not None else None
        if step is None:
            step = (stop - self.start) / 100 if stop else 0.01
            # no default step: at most 100 of the FMU's own fixed internal steps, so a model
            # integrating a long span (Reference Roberts: 1e7 s in steps of 1e-3 s) is not
            # asked for 1e8 internal steps in one fmi3DoStep
            internal = getattr(self.cs, "fixedInternalStepSize", None)
            if internal:
                step = min(step, 100 * float(internal))
        self.h = step
        span = round((stop - self.start) / step) if stop else n_steps
        self.n = max(4, min(n_steps, span))
        self.has_event_mode = bool(self.cs and self.cs.hasEventMode)
        self.might_return_early = bool(getattr(self.cs, "mightReturnEarlyFromDoStep", False))

    def instance(self, name: str, **kw: Any) -> _Instance3:
        return _Instance3(self, name, **kw)

    def input_values(self, k: int) -> list[tuple[Any, float]]:
        values = []
        for v in self.inputs:
            lo, hi, st = _num(v.min), _num(v.max), _num(v.start) or 0.0
            s = math.sin(0.7 * k)
            if lo is not None and hi is not None:
                value = 0.5 * (lo + hi) + 0.4 * (hi - lo) * s
            else:
                value = st + 0.1 * max(1.0, abs(st)) * s
                value = max(value, lo) if lo is not None else value
                value = min(value, hi) if hi is not None else value
            values.append((v, value))
        return values


class _Failed3(Exception):
    """An FMI 3 call of a nominal run that did not return fmi3OK/fmi3Warning."""

    def __init__(self, method: str, status: int, messages: list[tuple[int, str]],
                 text: str = "") -> None:
        if text:
            super().__init__(text)
            return
        label = {2: "Discard", 3: "Error", 4: "Fatal"}.get(status, str(status))
        said = " | ".join(m for _, m in messages[-2:]).strip()
        super().__init__(f"fmi3{method[0].upper()}{method[1:]} returned fmi3{label} in a "
                         "nominal run" + (f"; FMU says: {said}" if said else ""))


class _Instance3:
    """One FMI 3 co-simulation instance; ``call`` returns (status, result), logs are kept."""

    INSTANTIATE = "fmi3InstantiateCoSimulation"

    def __init__(self, host: _Host3, name: str, **kw: Any) -> None:
        self.host = host
        self.messages: list[tuple[int, str]] = []

        def log(env: Any, status: int, category: bytes, message: bytes) -> None:
            self.messages.append((status, message.decode(errors="replace")))

        self.fmu = WATCHDOG.call(f"dlopen({host.model_identifier})",
                                 self._fmpy_class(), guid=host.md.guid,
                                 unzipDirectory=host.unzipdir,
                                 modelIdentifier=host.model_identifier, instanceName=name)
        call = describe_call(self.INSTANTIATE, (), kw)
        try:
            WATCHDOG.call(call, self._instantiate, log, **kw)
        except Exception as err:
            if "instantiate" not in str(err):
                raise
            said = " | ".join(m for _, m in self.messages[-2:]).strip()
            why = (" (its modelDescription declares hasEventMode = true, so an importer may "
                   "ask for Event Mode)" if kw.get("eventModeUsed") else "")
            raise _Failed3(call, 3, [], f"{call} returned NULL{why}; "
                           + (f"FMU says: {said}" if said else "the FMU logged nothing")
                           ) from None
        self.alive = True

    @staticmethod
    def _fmpy_class() -> type:
        from fmpy.fmi3 import FMU3Slave

        return FMU3Slave

    def _instantiate(self, log: Callable[..., None], **kw: Any) -> None:
        self.fmu.instantiate(loggingOn=False, logMessage=log, **kw)

    def call(self, method: str, *args: Any, **kwargs: Any) -> tuple[int, Any]:
        from fmpy.fmi1 import FMICallException

        try:
            return 0, WATCHDOG.call(describe_call(method, args, kwargs, "fmi3"),
                                    getattr(self.fmu, method), *args, **kwargs)
        except FMICallException as err:
            return err.status, None

    def must(self, method: str, *args: Any, **kwargs: Any) -> Any:
        status, result = self.call(method, *args, **kwargs)
        if status > 1:
            raise _Failed3(method, status, self.messages)
        return result

    def init(self) -> None:
        self.must("enterInitializationMode", startTime=self.host.start)
        self.must("exitInitializationMode")

    def set_inputs(self, k: int) -> None:
        for v, value in self.host.input_values(k):
            self.must("setFloat64", [v.valueReference], [value])

    def read_outputs(self) -> list[float]:
        getters = {"Float64": "getFloat64", "Float32": "getFloat32", "Boolean": "getBoolean",
                   "Enumeration": "getInt64"}
        out = []
        for v in self.host.outputs:
            method = getters.get(v.type, f"get{v.type}")
            out.append(float(self.must(method, [v.valueReference])[0]))
        return out

    def event_mode(self, problems: list[Problem]) -> tuple[bool, float | None]:
        """fmi3UpdateDiscreteStates until converged: (terminate, next event time or None)."""
        for _ in range(100):
            need, terminate, _, _, defined, next_time = self.must("updateDiscreteStates")
            if terminate or not need:
                return bool(terminate), float(next_time) if defined else None
        problems.append(Problem("fmi3-event-mode", "fmi3UpdateDiscreteStates still returns "
                                "discreteStatesNeedUpdate = true after 100 calls"))
        return False, None

    def free(self) -> None:
        if self.alive:
            WATCHDOG.call(describe_call("fmi3FreeInstance"), self.fmu.freeInstance)
            self.alive = False


def _plain_run(inst: _Instance3, k0: int, k1: int, problems: list[Problem] | None = None
               ) -> np.ndarray:
    """Steps k0..k1-1 of h without Event Mode: set inputs, read outputs, doStep; outputs at
    points k0..k1."""
    host, rows = inst.host, []
    for k in range(k0, k1 + 1):
        inst.set_inputs(k)
        rows.append(inst.read_outputs())
        if k == k1:
            break
        t = host.start + k * host.h
        _, terminate, early, last = inst.must("doStep", currentCommunicationPoint=t,
                                              communicationStepSize=host.h)
        if problems is not None and early:
            problems.append(Problem("fmi3-calling-sequence", f"fmi3DoStep at t={t} returned "
                                    "earlyReturn = true although the FMU was instantiated "
                                    "with earlyReturnAllowed = false"))
        if terminate:
            break
    return np.array(rows, dtype=float).reshape(len(rows), len(host.outputs))


def _check_calling_sequence(host: _Host3, ctx: dict) -> list[Problem]:
    problems: list[Problem] = []
    inst = host.instance("sequence")
    inst.init()
    rows = _plain_run(inst, 0, host.n, problems)
    inst.must("terminate")
    errors = [m for s, m in inst.messages if s >= 3]
    inst.free()
    ctx["reference"] = rows
    if errors:
        problems.append(Problem("fmi3-calling-sequence", f"error messages in a nominal run: "
                                                         f"{errors[0]}"))
    if rows.size and not np.isfinite(rows).all():
        k, j = np.argwhere(~np.isfinite(rows))[0]
        problems.append(Problem("fmi3-calling-sequence", f"output {host.outputs[j].name} is "
                                                         f"{rows[k, j]} at step {k}"))
    return problems


def _check_event_mode(host: _Host3, ctx: dict) -> list[Problem]:
    """An importer honouring nextEventTime: every step ends at the announced event at the
    latest; eventHandlingNeeded and the announced events are handled in Event Mode."""
    if not host.has_event_mode:
        return []
    problems: list[Problem] = []
    inst = host.instance("events", eventModeUsed=True)
    inst.init()  # now in Event Mode (eventModeUsed)
    inst.set_inputs(0)
    terminate, next_event = inst.event_mode(problems)
    inst.must("enterStepMode")
    t, stop, k = host.start, host.start + host.n * host.h, 0
    while t < stop - 1e-12 and not terminate and k < 10 * host.n:
        if next_event is not None and next_event < t - 1e-12:
            problems.append(Problem("fmi3-event-mode", f"nextEventTime {next_event} is before "
                                                       f"the current time {t}"))
            break
        end = min(t + host.h, stop)
        if next_event is not None and next_event > t + 1e-12:
            end = min(end, next_event)
        event, terminate, early, last = inst.must("doStep", currentCommunicationPoint=t,
                                                  communicationStepSize=end - t)
        if early:
            problems.append(Problem("fmi3-early-return", f"fmi3DoStep at t={t} returned early "
                                    "although earlyReturnAllowed = false"))
        t, k = end, k + 1
        reached = next_event is not None and abs(t - next_event) <= 1e-9 * max(1.0, abs(t))
        if event or reached:
            inst.must("enterEventMode")
            inst.set_inputs(k)
            inst.read_outputs()
            terminate, next_event = inst.event_mode(problems)
            inst.must("enterStepMode")
        else:
            inst.set_inputs(k)
            inst.read_outputs()
    errors = [m for s, m in inst.messages if s >= 3]
    if not terminate:
        inst.must("terminate")
    inst.free()
    if errors:
        problems.append(Problem("fmi3-event-mode", f"error messages in an Event Mode run: "
                                                   f"{errors[0]}"))
    return problems


def _check_early_return(host: _Host3, ctx: dict) -> list[Problem]:
    """Steps of 2.5 default steps with early return allowed: an early return must be
    declared (mightReturnEarlyFromDoStep) and end inside the step; the run continues from
    lastSuccessfulTime."""
    problems: list[Problem] = []
    inst = host.instance("early", eventModeUsed=host.has_event_mode, earlyReturnAllowed=True)
    inst.init()
    if host.has_event_mode:
        inst.set_inputs(0)
        inst.event_mode(problems)
        inst.must("enterStepMode")
    t, stop, k, terminate = host.start, host.start + host.n * host.h, 0, False
    while t < stop - 1e-12 and not terminate and k < 10 * host.n:
        h = min(2.5 * host.h, stop - t)
        event, terminate, early, last = inst.must("doStep", currentCommunicationPoint=t,
                                                  communicationStepSize=h)
        k += 1
        if early:
            if not host.might_return_early:
                # an importer that allowed early return copes; the capability flag (4.4)
                # should announce it
                problems.append(Problem("fmi3-early-return", f"fmi3DoStep at t={t} returned "
                                        "early, but the FMU declares "
                                        "mightReturnEarlyFromDoStep = false",
                                        requirement=RECOMMENDED))
                break
            if not t < last <= t + h * (1 + 1e-12):
                problems.append(Problem("fmi3-early-return", f"early return from the step "
                                        f"[{t}, {t + h}] with lastSuccessfulTime {last}"))
                break
            t = float(last)
        else:
            t += h
        if host.has_event_mode and event:
            inst.must("enterEventMode")
            inst.set_inputs(k)
            inst.read_outputs()
            terminate, _ = inst.event_mode(problems)
            inst.must("enterStepMode")
    inst.free()
    return problems


def _check_fmu_state(host: _Host3, ctx: dict) -> list[Problem]:
    if not host.cs.canGetAndSetFMUstate:
        return []
    problems: list[Problem] = []
    k = host.n // 2
    inst = host.instance("state")
    inst.init()
    _plain_run(inst, 0, k)
    inst.set_inputs(k)  # the state at point k, inputs of k set
    state = inst.must("getFMUState")
    serialized = (inst.must("serializeFMUState", state)
                  if host.cs.canSerializeFMUstate else None)
    first = _plain_run(inst, k, host.n)
    inst.must("setFMUState", state)
    again = _plain_run(inst, k, host.n)
    diff = _differs(again, first, ignore=host.irreproducible)
    if diff:
        problems.append(Problem("fmi3-fmu-state", "the run after fmi3SetFMUState differs: "
                                + diff))
    if serialized is not None:
        restored = inst.must("deserializeFMUState", serialized)
        inst.must("setFMUState", restored)
        third = _plain_run(inst, k, host.n)
        diff = _differs(third, first, ignore=host.irreproducible)
        if diff:
            problems.append(Problem("fmi3-fmu-state", "the run after fmi3DeserializeFMUState "
                                    "differs: " + _out_name(host, diff)))
        inst.must("freeFMUState", restored)
    inst.must("freeFMUState", state)
    inst.free()
    return problems


def _check_wrong_state(host: _Host3, ctx: dict) -> list[Problem]:
    problems: list[Problem] = []
    inst = host.instance("wrong")
    status, _ = inst.call("doStep", currentCommunicationPoint=host.start,
                          communicationStepSize=host.h)
    if status == 0:
        problems.append(Problem("fmi3-wrong-state", "fmi3DoStep before initialisation returned "
                                                    "fmi3OK"))
    inst.free()
    inst = host.instance("wrong2")
    inst.init()  # Step Mode (eventModeUsed = false)
    status, _ = inst.call("enterEventMode")
    if status == 0:
        problems.append(Problem("fmi3-wrong-state", "fmi3EnterEventMode returned fmi3OK for an "
                                "instance made with eventModeUsed = false"))
    inst.free()
    return problems


DYNAMIC = {
    "fmi3-calling-sequence": _check_calling_sequence,
    "fmi3-event-mode": _check_event_mode,
    "fmi3-early-return": _check_early_return,
    "fmi3-fmu-state": _check_fmu_state,
    "fmi3-wrong-state": _check_wrong_state,
}

