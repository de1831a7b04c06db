"""Small FMI 3.0 co-simulation FMUs written in C (tests/third_party/fmi3_models.c), built as a
third-party tool would ship them: gcc against fmpy's FMI 3 headers, zipped with a
modelDescription.xml (binaries/x86_64-linux, FMI 3.0 sec. 2.5.1.4).

Variables are ``(name, type, causality, variability, value reference, start, extra)``;
``extra`` may hold ``dimension`` (array size), ``unit``, and a Clock's attributes
(``intervalVariability``, ``intervalDecimal``, ``shiftDecimal``, ``supportsFraction`` ...)."""

from __future__ import annotations

import hashlib
import shutil
import subprocess
import zipfile
from dataclasses import dataclass, field, replace
from pathlib import Path
from xml.etree.ElementTree import Element, SubElement, indent, tostring

import fmpy

HERE = Path(__file__).resolve().parent
MODE_ITEMS = ("slow", "normal", "fast")  # Enumeration type Mode: values 1, 2, 3
# the Feedthrough's types in value-reference order: u_T = 2 i + 1, y_T = 2 i + 2
TYPES = ("Float64", "Float32", "Int8", "UInt8", "Int16", "UInt16", "Int32", "UInt32", "Int64",
         "UInt64", "Boolean", "String", "Binary", "Enumeration")


@dataclass(frozen=True)
class Spec3:
    name: str
    model: str  # MODEL_<model> in fmi3_models.c
    variables: tuple[tuple, ...]
    dependencies: dict[str, tuple[str, ...]] = field(default_factory=dict)
    event_mode: bool = False
    stop_time: float = 1.0
    step: float = 0.125
    scheduled: bool = False  # a Scheduled Execution FMU (fmi3_scheduled.c), not co-simulation
    clock_types: dict[str, dict[str, str]] = field(default_factory=dict)  # ClockType attributes
    defines: tuple[str, ...] = ()  # C macros besides MODEL_<model> (start values the C sets)


def _start(kind: str) -> str:
    return {"Boolean": "false", "String": "in", "Binary": "", "Enumeration": "1"}.get(
        kind, "1.5" if kind.startswith("Float") else "1")


FEEDTHROUGH3 = Spec3("Feedthrough3", "FEEDTHROUGH", (
    *[v for i, kind in enumerate(TYPES) for v in (
        (f"u_{kind}", kind, "input", "discrete" if not kind.startswith("Float") else
         "continuous", 2 * i + 1, _start(kind), {}),
        (f"y_{kind}", kind, "output", "discrete" if not kind.startswith("Float") else
         "continuous", 2 * i + 2, None, {}))],
    ("ua", "Float64", "input", "continuous", 101, "0 0 0", {"dimension": 3}),
    ("ya", "Float64", "output", "continuous", 102, None, {"dimension": 3}),
), dependencies={**{f"y_{k}": (f"u_{k}",) for k in TYPES}, "ya": ("ua",)})

TIME_EVENTS3 = Spec3("TimeEvents3", "TIMEEVENTS", (
    ("period", "Float64", "parameter", "fixed", 0, "0.1", {"unit": "s"}),
    ("announce", "Boolean", "parameter", "fixed", 4, "true", {}),
    ("u", "Float64", "input", "continuous", 1, "0.0", {}),
    ("q", "Float64", "output", "discrete", 2, None, {}),
    ("n", "Int32", "output", "discrete", 3, None, {}),
), dependencies={"q": (), "n": ()}, event_mode=True)

TERMINATOR3 = Spec3("Terminator3", "TERMINATOR", (
    ("stop_at", "Float64", "parameter", "fixed", 5, "0.75", {"unit": "s"}),
    ("x", "Float64", "output", "continuous", 6, None, {"unit": "s"}),
), dependencies={"x": ()})

# TimeEvents with its output clock "ticked", active at each of its events
TICKER3 = Spec3("Ticker3", "TIMEEVENTS", (
    *TIME_EVENTS3.variables,
    ("ticked", "Clock", "output", "discrete", 17, None, {"intervalVariability": "triggered"}),
), dependencies={"q": (), "n": (), "ticked": ()}, event_mode=True)

# first: the clock's first interval (asked in Initialization Mode); repeat: its ticks at
# interval 0 after each tick; period: its interval after a tick at interval 0
# events at k period for the bits k set in pattern (771: 0, 1, 8, 9 s), announced as
# nextEventTime; its output clock "ticked" active at each (the Reference FMU Clocks' inClock2
# ticks, "triggered by the simulation algorithm at 0, 1, 8 and 9")
PULSES3 = Spec3("Pulses3", "PULSES", (
    ("period", "Float64", "parameter", "fixed", 0, "1.0", {"unit": "s"}),
    ("pattern", "Int32", "parameter", "fixed", 19, "771", {}),
    ("n", "Int32", "output", "discrete", 3, None, {}),
    ("ticked", "Clock", "output", "discrete", 17, None, {"intervalVariability": "triggered"}),
), dependencies={"n": (), "ticked": ()}, event_mode=True, stop_time=10.0)

COUNTDOWN3 = Spec3("Countdown3", "COUNTDOWN", (
    ("first", "Float64", "parameter", "fixed", 7, "0.1", {"unit": "s"}),
    ("repeat", "Int32", "parameter", "fixed", 18, "0", {}),
    ("period", "Float64", "parameter", "fixed", 0, "0.1", {"unit": "s"}),
    ("tick", "Clock", "input", "discrete", 10, None, {"intervalVariability": "countdown"}),
    ("u", "Float64", "input", "continuous", 1, "0.0", {}),
    ("q", "Float64", "output", "discrete", 2, None, {}),
    ("n", "Int32", "output", "discrete", 3, None, {}),
), dependencies={"q": (), "n": ()}, event_mode=True, stop_time=2.0)
# Countdown ticking twice at each instant (repeat 1: interval 0 once after each tick)
COUNTDOWN_TWICE3 = replace(
    COUNTDOWN3, name="CountdownTwice3", defines=("COUNTDOWN_REPEAT=1",),
    variables=tuple(v if v[0] != "repeat" else (*v[:5], "1", v[6])
                    for v in COUNTDOWN3.variables))

# TimeEvents with its time tolerance and t_event, the FMU's own time at its last event (with
# tolerance 0 and period 1/3 s: events at doubles that are not whole nanoseconds)
THIRDS3 = Spec3("Thirds3", "TIMEEVENTS", (
    *TIME_EVENTS3.variables,
    ("tolerance", "Float64", "parameter", "fixed", 8, "1e-09", {"unit": "s"}),
    ("t_event", "Float64", "output", "discrete", 9, None, {"unit": "s"}),
), dependencies={"q": (), "n": (), "t_event": ()}, event_mode=True, stop_time=2.0)


def clocked(name: str, variability: str, **attributes: str) -> Spec3:
    """The Clocked model with its input clock "tick" of ``variability`` (modelDescription
    ``attributes`` such as intervalDecimal); q is the FMU's time at its last tick. Its interval
    and shift are the parameters interval and shift (fmi3GetIntervalDecimal, ...Shift...), or
    interval_counter and shift_counter over resolution (the Fraction functions)."""
    return Spec3(name, "CLOCKED", (
        ("interval_counter", "UInt64", "parameter", "fixed", 14, "3", {}),
        ("shift_counter", "UInt64", "parameter", "fixed", 15, "1", {}),
        ("resolution", "UInt64", "parameter", "fixed", 16, "10", {}),
        ("interval", "Float64", "parameter", "fixed", 11, "0.3", {"unit": "s"}),
        ("shift", "Float64", "parameter", "fixed", 12, "0.1", {"unit": "s"}),
        ("growth", "Float64", "parameter", "fixed", 13, "1.0", {}),
        ("tick", "Clock", "input", "discrete", 10, None,
         {"intervalVariability": variability, **attributes}),
        ("q", "Float64", "output", "discrete", 2, None, {"unit": "s"}),
        ("n", "Int32", "output", "discrete", 3, None, {}),
    ), dependencies={"q": (), "n": ()}, event_mode=True, stop_time=2.0)


CLOCKED3 = {kind: clocked(f"Clocked{kind.title()}3", kind, **attributes) for kind, attributes in (
    ("constant", {"intervalDecimal": "0.3", "shiftDecimal": "0.1"}),
    ("fixed", {}), ("tunable", {}))}
CLOCKED3["fraction"] = clocked("ClockedFraction3", "fixed", supportsFraction="true")
# fixed and tunable clocks that declare their interval and shift (0.3 s, 0.1 s): the importer
# asks neither (FMI 3.0 sec. 2.2.8.2), so the FMU's parameters interval and shift go unheard
CLOCKED3["declared"] = clocked("ClockedDeclared3", "fixed", intervalDecimal="0.3",
                               shiftDecimal="0.1")
# a changing clock (first tick interval after the start, then interval times growth after
# each tick, told in the Event Mode where it ticked)
CLOCKED3["changing"] = replace(clocked("ClockedChanging3", "changing"),
                               defines=("CLOCK_CHANGING",))
CLOCKED3["steady"] = clocked("ClockedSteady3", "tunable", intervalDecimal="0.3",
                             shiftDecimal="0.1")
# a constant clock with its interval from its ClockType "Tick" and its own shift (0.1 s)
# overriding the type's (0.5 s): ticks as ClockedConstant3's
CLOCKED3["typed"] = replace(
    clocked("ClockedTyped3", "constant", declaredType="Tick", shiftDecimal="0.1"),
    clock_types={"Tick": {"intervalVariability": "constant", "intervalDecimal": "0.3",
                          "shiftDecimal": "0.5"}})

# the Scheduled Execution FMU of fmi3_scheduled.c: partitions fast, slow, alarm, kick
TASKS3 = Spec3("Tasks3", "TASKS", (
    ("slow_interval", "Float64", "parameter", "fixed", 10, "0.25", {"unit": "s"}),
    ("slow_shift", "Float64", "parameter", "fixed", 11, "0.0", {"unit": "s"}),
    ("alarm_after", "Int32", "parameter", "fixed", 12, "5", {}),
    ("alarm_delay", "Float64", "parameter", "fixed", 13, "0.05", {"unit": "s"}),
    ("fast", "Clock", "input", "discrete", 1, None,
     {"intervalVariability": "constant", "intervalDecimal": "0.1", "priority": "1"}),
    ("slow", "Clock", "input", "discrete", 2, None,
     {"intervalVariability": "fixed", "priority": "0"}),
    ("alarm", "Clock", "input", "discrete", 3, None,
     {"intervalVariability": "countdown", "priority": "2"}),
    ("kick", "Clock", "input", "discrete", 4, None,
     {"intervalVariability": "triggered", "priority": "3"}),
    ("done", "Clock", "output", "discrete", 5, None, {"intervalVariability": "triggered"}),
    ("u", "Float64", "input", "discrete", 20, "0.0", {}),
    ("n_fast", "Int32", "output", "discrete", 21, None, {}),
    ("n_slow", "Int32", "output", "discrete", 22, None, {}),
    ("n_alarm", "Int32", "output", "discrete", 23, None, {}),
    ("n_kick", "Int32", "output", "discrete", 24, None, {}),
    ("y", "Float64", "output", "discrete", 25, None, {}),
    ("t_alarm", "Float64", "output", "discrete", 26, None, {"unit": "s"}),
    ("t_kick", "Float64", "output", "discrete", 27, None, {"unit": "s"}),
), dependencies={"done": (), "n_fast": (), "n_slow": (), "n_alarm": (), "n_kick": (),
                 "y": ("u",), "t_alarm": (), "t_kick": ()}, scheduled=True)

# Tasks3 with slow a changing clock: first after slow_interval, each next interval doubled
TASKS_CHANGING3 = replace(
    TASKS3, name="TasksChanging3", defines=("SLOW_CHANGING",), stop_time=2.0,
    variables=tuple(v if v[0] != "slow" else (*v[:6], {"intervalVariability": "changing",
                                                       "priority": "0"})
                    for v in TASKS3.variables))

# a co-simulation FMU with a triggered input clock "tick" (FMI 3.0 sec. 2.2.8.2: it ticks
# when the importer says, here an output clock connected to it): at each tick n counts it, q is
# the FMU's time and y its clocked input u; it logs "tick at t = <q, %.17g>" and refuses
# fmi3SetClock outside Event Mode
TRIGGERED3 = Spec3("Triggered3", "CLOCKED", (
    ("tick", "Clock", "input", "discrete", 10, None, {"intervalVariability": "triggered"}),
    ("u", "Int32", "input", "discrete", 1, "0", {"clocks": "10"}),
    ("q", "Float64", "output", "discrete", 2, None, {"unit": "s", "clocks": "10"}),
    ("n", "Int32", "output", "discrete", 3, None, {"clocks": "10"}),
    ("y", "Int32", "output", "discrete", 9, None, {"clocks": "10"}),
), dependencies={"q": (), "n": (), "y": ("u",)}, event_mode=True, stop_time=10.0,
    defines=("CLOCK_TRIGGERED",))

SPECS3 = (FEEDTHROUGH3, TIME_EVENTS3, TERMINATOR3, COUNTDOWN3, THIRDS3, *CLOCKED3.values(),
          TASKS3, TICKER3, PULSES3, COUNTDOWN_TWICE3, TASKS_CHANGING3, TRIGGERED3)


def model_description(spec: Spec3) -> bytes:
    root = Element("fmiModelDescription", {
        "fmiVersion": "3.0", "modelName": spec.name,
        "instantiationToken": "{" + hashlib.md5(spec.name.encode()).hexdigest() + "}",
        "generationTool": "tests/third_party (C)", "variableNamingConvention": "structured"})
    if spec.scheduled:
        SubElement(root, "ScheduledExecution", {"modelIdentifier": spec.name})
    else:
        SubElement(root, "CoSimulation", {
            "modelIdentifier": spec.name, "canHandleVariableCommunicationStepSize": "true",
            "hasEventMode": "true" if spec.event_mode else "false",
            "mightReturnEarlyFromDoStep": "true" if spec.event_mode else "false"})
    units = sorted({v[6]["unit"] for v in spec.variables if "unit" in v[6]})
    if units:
        defs = SubElement(root, "UnitDefinitions")
        for unit in units:
            SubElement(SubElement(defs, "Unit", {"name": unit}), "BaseUnit", {"s": "1"})
    enumerations = any(v[1] == "Enumeration" for v in spec.variables)
    if enumerations or spec.clock_types:
        types = SubElement(root, "TypeDefinitions")
        for name, attributes in spec.clock_types.items():
            SubElement(types, "ClockType", {"name": name, **attributes})
    if enumerations:
        enum = SubElement(types, "EnumerationType", {"name": "Mode"})
        for value, item in enumerate(MODE_ITEMS, start=1):
            SubElement(enum, "Item", {"name": item, "value": str(value)})
    SubElement(root, "DefaultExperiment", {"startTime": "0.0", "stopTime": repr(spec.stop_time),
                                           "stepSize": repr(spec.step)})
    mv = SubElement(root, "ModelVariables")
    SubElement(mv, "Float64", {"name": "time", "valueReference": "999",
                               "causality": "independent", "variability": "continuous"})
    vrs = {}
    for name, kind, causality, variability, vr, start, extra in spec.variables:
        vrs[name] = vr
        attrib = {"name": name, "valueReference": str(vr), "causality": causality,
                  "variability": variability}
        if "unit" in extra:
            attrib["unit"] = extra["unit"]
        if "clocks" in extra:  # a clocked variable: its clocks' value references
            attrib["clocks"] = extra["clocks"]
        if kind == "Clock":
            attrib.update({k: v for k, v in extra.items() if k not in ("unit", "clocks")})
        if kind == "Enumeration":
            attrib["declaredType"] = "Mode"
        if causality == "output" and kind != "Clock":
            attrib["initial"] = "calculated"
        elif causality == "parameter":
            attrib["initial"] = "exact"
        if start is not None and kind not in ("String", "Binary"):
            attrib["start"] = start
        var = SubElement(mv, kind, attrib)
        if start is not None and kind in ("String", "Binary"):
            SubElement(var, "Start", {"value": start})
        if "dimension" in extra:
            SubElement(var, "Dimension", {"start": str(extra["dimension"])})
    ms = SubElement(root, "ModelStructure")
    for name, _kind, causality, *_ in spec.variables:
        if causality == "output":
            attrib = {"valueReference": str(vrs[name])}
            if name in spec.dependencies:
                attrib["dependencies"] = " ".join(str(vrs[d]) for d in spec.dependencies[name])
            SubElement(ms, "Output", attrib)
    for name, kind, causality, *_, extra in spec.variables:
        # a clocked output is no initial unknown (FMI 3.0 sec. 2.4.8: InitialUnknown lists
        # the outputs that are not clocked)
        if causality == "output" and kind != "Clock" and "clocks" not in extra:
            SubElement(ms, "InitialUnknown", {"valueReference": str(vrs[name])})
    indent(root)
    return b'<?xml version="1.0" encoding="UTF-8"?>\n' + tostring(root, encoding="utf-8")


def build(spec: Spec3, out_dir: Path, work: Path) -> Path:
    headers = Path(fmpy.__file__).parent / "c-code"
    lib = work / f"{spec.name}.so"
    model = "fmi3_scheduled.c" if spec.scheduled else "fmi3_models.c"
    subprocess.run(["gcc", "-std=c99", "-D_DEFAULT_SOURCE", "-Wall", "-Wextra", "-Werror",
                    "-shared", "-fPIC", "-O1", f"-I{headers}", f"-DMODEL_{spec.model}",
                    *(["-DSCHEDULED_EXECUTION"] if spec.scheduled else []),
                    *(f"-D{d}" for d in spec.defines), "-o", str(lib),
                    str(HERE / model), str(HERE / "fmi3_stubs.c"), "-lm"],
                   check=True, capture_output=True, text=True)
    path = out_dir / f"{spec.name}.fmu"
    with zipfile.ZipFile(path, "w") as z:
        z.writestr("modelDescription.xml", model_description(spec))
        z.write(lib, f"binaries/x86_64-linux/{spec.name}.so")
    return path


def build_reference(model: str, source: Path, out_dir: Path) -> Path:
    """The Modelica Reference FMU ``model`` (FMI 3.0) built from the Reference-FMUs sources
    at ``source`` (a checkout or its git directory) as its CMakeLists.txt builds it:
    ``model/model.c``, ``src/fmi3Functions.c`` and ``src/cosimulation.c`` with FMI_VERSION=3
    and DISABLE_PREFIX, ``model/FMI3.xml`` as modelDescription.xml."""
    work = out_dir / f"reference-{model}"
    if (source / "HEAD").is_file():  # a git directory: its newest tree
        work.mkdir(parents=True, exist_ok=True)
        archive = subprocess.run(["git", f"--git-dir={source}", "archive", "HEAD", "include",
                                  "src", model], check=True, capture_output=True).stdout
        subprocess.run(["tar", "x", "-C", str(work)], input=archive, check=True)
        source = work
    lib = out_dir / f"{model}.so"
    subprocess.run(["gcc", "-shared", "-fPIC", "-O2", "-DFMI_VERSION=3", "-DDISABLE_PREFIX",
                    f"-I{source / 'include'}", f"-I{source / model}", "-o", str(lib),
                    str(source / model / "model.c"), str(source / "src" / "fmi3Functions.c"),
                    str(source / "src" / "cosimulation.c"), "-lm"],
                   check=True, capture_output=True, text=True)
    path = out_dir / f"{model}.fmu"
    with zipfile.ZipFile(path, "w") as z:
        z.write(source / model / "FMI3.xml", "modelDescription.xml")
        z.write(lib, f"binaries/x86_64-linux/{model}.so")
    return path


def build_all3(out_dir: Path) -> dict[str, Path]:
    if shutil.which("gcc") is None:
        raise FileNotFoundError("gcc is not installed")
    work = out_dir / "build3"
    work.mkdir(parents=True, exist_ok=True)
    return {spec.name: build(spec, out_dir, work) for spec in SPECS3}
