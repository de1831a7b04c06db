"""Small FMI 2.0 co-simulation FMUs written in C (no pythonfmu), built for the tests as a
third-party tool would ship them: ``build_all(out_dir)`` compiles ``*.c`` here with gcc against
fmpy's FMI 2 headers and zips each with its modelDescription.xml.

Variables are ``(name, type, causality, variability, value reference, start, extra)``; a type
``Enumeration`` uses the Integer value-reference space and the ``Mode`` type (items 1..3).
"""

from __future__ import annotations

import hashlib
import shutil
import subprocess
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from xml.etree.ElementTree import Element, SubElement, indent, tostring

import fmpy

HERE = Path(__file__).resolve().parent
MODE_ITEMS = ("slow", "normal", "fast")  # Enumeration type Mode: values 1, 2, 3


@dataclass(frozen=True)
class Spec:
    """One test FMU: its C source, variables, flags and default experiment."""

    name: str
    source: str
    variables: tuple[tuple, ...]
    # output name -> names it depends on; an output missing here has no dependencies attribute
    dependencies: dict[str, tuple[str, ...]] = field(default_factory=dict)
    variable_step: bool = True
    stop_time: float = 1.0
    step: float = 0.125
    defines: tuple[str, ...] = ()  # C preprocessor switches, e.g. HANG_ON_NAN_STEP


ALL_TYPES = Spec("AllTypes", "all_types.c", (
    ("gain", "Real", "parameter", "fixed", 0, "2.0", {"unit": "1"}),
    ("u", "Real", "input", "continuous", 1, "0.5", {"unit": "1"}),
    ("y", "Real", "output", "continuous", 2, None, {"unit": "1"}),
    ("offset", "Integer", "parameter", "fixed", 0, "10", {}),
    ("ui", "Integer", "input", "discrete", 1, "1", {}),
    ("yi", "Integer", "output", "discrete", 2, None, {}),
    ("mode", "Enumeration", "input", "discrete", 3, "1", {}),
    ("next_mode", "Enumeration", "output", "discrete", 4, None, {}),
    ("level", "Enumeration", "parameter", "fixed", 5, "1", {}),
    ("invert", "Boolean", "parameter", "fixed", 0, "false", {}),
    ("ub", "Boolean", "input", "discrete", 1, "false", {}),
    ("yb", "Boolean", "output", "discrete", 2, None, {}),
    ("label", "String", "parameter", "fixed", 0, "tag", {}),
    ("us", "String", "input", "discrete", 1, "in", {}),
    ("ys", "String", "output", "discrete", 2, None, {}),
), dependencies={"y": (), "yi": (), "next_mode": (), "yb": (), "ys": ()})

TERMINATOR = Spec("Terminator", "terminator.c", (
    ("stop_at", "Real", "parameter", "fixed", 0, "0.75", {"unit": "s"}),
    ("x", "Real", "output", "continuous", 1, None, {"unit": "1"}),
    ("steps", "Integer", "output", "discrete", 0, None, {}),
), dependencies={"x": (), "steps": ()}, stop_time=0.75)

DISCARDER = Spec("Discarder", "discarder.c", (
    ("max_step", "Real", "parameter", "fixed", 0, "0.125", {"unit": "s", "min": "0.0"}),
    ("u", "Real", "input", "continuous", 1, "1.0", {"unit": "1"}),
    ("x", "Real", "output", "continuous", 2, None, {"unit": "1"}),
), dependencies={"x": ()})

# the same binary, but declaring it cannot handle variable communication step sizes
DISCARDER_FIXED = Spec("DiscarderFixed", "discarder.c", DISCARDER.variables,
                       dependencies={"x": ()}, variable_step=False)
# ... and declaring its own step (DefaultExperiment stepSize) shorter than the output interval
DISCARDER_FIXED_STEP = Spec("DiscarderFixedStep", "discarder.c", DISCARDER.variables,
                            dependencies={"x": ()}, variable_step=False, step=0.05)

# y = k u depends on u; z = integral of u does not (both declared)
FEEDTHROUGH = Spec("Feedthrough", "feedthrough.c", (
    ("k", "Real", "parameter", "fixed", 0, "3.0", {"unit": "1"}),
    ("u", "Real", "input", "continuous", 1, "0.0", {"unit": "1"}),
    ("y", "Real", "output", "continuous", 2, None, {"unit": "1"}),
    ("z", "Real", "output", "continuous", 3, None, {"unit": "1"}),
), dependencies={"y": ("u",), "z": ()})

# the same FMU without any dependencies attribute (FMI 2.0.4 sec. 2.2.8: depends on all inputs)
FEEDTHROUGH_UNDECLARED = Spec("FeedthroughUndeclared", "feedthrough.c", FEEDTHROUGH.variables)

EVENTS = Spec("Events", "events.c", (
    ("period", "Real", "parameter", "fixed", 0, "0.1", {"unit": "s", "min": "1e-3"}),
    ("u", "Real", "input", "continuous", 1, "0.0", {"unit": "1"}),
    ("q", "Real", "output", "discrete", 2, None, {"unit": "1"}),
    ("n", "Integer", "output", "discrete", 0, None, {}),
), dependencies={"q": (), "n": ()})

# y = k u declared independent of u: wrong (a required rule of sec. 2.2.8 broken)
FEEDTHROUGH_LYING = Spec("FeedthroughLying", "feedthrough.c", FEEDTHROUGH.variables,
                         dependencies={"y": (), "z": ()})

# y = k u named next_event_time: an FMU announcing its next event (the FMI 2 convention of the
# master) at whatever time its input says, a time in the past included
ANNOUNCER = Spec("Announcer", "feedthrough.c", (
    ("k", "Real", "parameter", "fixed", 0, "1.0", {"unit": "1"}),
    ("u", "Real", "input", "continuous", 1, "0.5", {"unit": "s"}),
    ("next_event_time", "Real", "output", "continuous", 2, None, {"unit": "s"}),
    ("z", "Real", "output", "continuous", 3, None, {"unit": "s"}),
), dependencies={"next_event_time": ("u",), "z": ()})

# an output whose value reference the binary does not have: every fmi2GetReal of it fails
BAD_REFERENCE = Spec("BadReference", "feedthrough.c", (
    *FEEDTHROUGH.variables,
    ("w", "Real", "output", "continuous", 9, None, {"unit": "1"}),
), dependencies={"y": ("u",), "z": (), "w": ()})

# doStep with a NaN step size never returns
HANGER = Spec("Hanger", "events.c", EVENTS.variables, dependencies=EVENTS.dependencies,
              defines=("HANG_ON_NAN_STEP",))

# hostile.c: one FMU per misbehaviour (built only by the tests that use them, build_hostile)
_HOSTILE_VARIABLES = (
    ("u", "Real", "input", "continuous", 0, "0.5", {"unit": "1"}),
    ("y", "Real", "output", "continuous", 1, None, {"unit": "1"}),
)
HOSTILE = {name: Spec(name, "hostile.c", _HOSTILE_VARIABLES, dependencies={"y": ("u",)},
                      defines=defines)
           for name, defines in (
               ("SpinInInstantiate", ("ON_INSTANTIATE=spin()",)),
               ("BlockInInstantiate", ("ON_INSTANTIATE=block()",)),
               ("SpinInDoStep", ("ON_STEP=spin()",)),
               ("BlockInDoStep", ("ON_STEP=block()",)),
               ("SegfaultInDoStep", ("ON_STEP=segfault()",)),
               ("AbortInDoStep", ("ON_STEP=abort()",)),
               ("ExitInDoStep", ("ON_STEP=exit(3)",)),
               ("NanOutput", ("NAN_OUTPUT",)),
               ("SlowFirstStep", ("ON_STEP=slow_once()",)),
           )}

SPECS = (ALL_TYPES, TERMINATOR, DISCARDER, DISCARDER_FIXED, DISCARDER_FIXED_STEP, FEEDTHROUGH,
         FEEDTHROUGH_UNDECLARED, EVENTS, FEEDTHROUGH_LYING, HANGER, ANNOUNCER, BAD_REFERENCE)


def model_description(spec: Spec) -> bytes:
    """modelDescription.xml of ``spec`` (FMI 2.0 co-simulation)."""
    root = Element("fmiModelDescription", {
        "fmiVersion": "2.0", "modelName": spec.name,
        "guid": "{" + hashlib.md5(spec.name.encode()).hexdigest() + "}",
        "generationTool": "tests/third_party (C)", "variableNamingConvention": "flat"})
    SubElement(root, "CoSimulation", {
        "modelIdentifier": spec.name, "canHandleVariableCommunicationStepSize":
        "true" if spec.variable_step else "false", "canGetAndSetFMUstate": "true",
        "canSerializeFMUstate": "true", "canNotUseMemoryManagementFunctions": "true"})
    units = sorted({v[6]["unit"] for v in spec.variables if "unit" in v[6]})
    if units:
        defs = SubElement(root, "UnitDefinitions")
        for unit in units:
            u = SubElement(defs, "Unit", {"name": unit})
            SubElement(u, "BaseUnit", {"s": "1"} if unit == "s" else {})
    if any(v[1] == "Enumeration" for v in spec.variables):
        types = SubElement(root, "TypeDefinitions")
        enum = SubElement(SubElement(types, "SimpleType", {"name": "Mode"}), "Enumeration")
        for value, item in enumerate(MODE_ITEMS, start=1):
            SubElement(enum, "Item", {"name": item, "value": str(value)})
    SubElement(root, "DefaultExperiment", {"startTime": "0.0", "stopTime": repr(spec.stop_time),
                                           "stepSize": repr(spec.step)})
    mv = SubElement(root, "ModelVariables")
    index = {}
    for i, (name, kind, causality, variability, vr, start, extra) in enumerate(spec.variables):
        index[name] = i + 1
        attrib = {"name": name, "valueReference": str(vr), "causality": causality,
                  "variability": variability}
        if causality == "output":
            attrib["initial"] = "calculated"
        elif causality == "parameter":
            attrib["initial"] = "exact"
        sv = SubElement(mv, "ScalarVariable", attrib)
        type_attrib = dict(extra)
        if kind == "Enumeration":
            type_attrib["declaredType"] = "Mode"
        if start is not None:
            type_attrib["start"] = start
        SubElement(sv, kind, type_attrib)
    ms = SubElement(root, "ModelStructure")
    outputs = [v[0] for v in spec.variables if v[2] == "output"]
    out_node = SubElement(ms, "Outputs")
    init_node = SubElement(ms, "InitialUnknowns")
    for name in outputs:
        attrib = {"index": str(index[name])}
        if name in spec.dependencies:
            attrib["dependencies"] = " ".join(str(index[d]) for d in spec.dependencies[name])
        SubElement(out_node, "Unknown", attrib)
        SubElement(init_node, "Unknown", {"index": str(index[name])})
    indent(root)
    return b'<?xml version="1.0" encoding="UTF-8"?>\n' + tostring(root, encoding="utf-8")


def build(spec: Spec, out_dir: Path, work: Path) -> Path:
    """Compile ``spec`` with gcc and zip it as ``out_dir/<name>.fmu``."""
    headers = Path(fmpy.__file__).parent / "c-code"
    lib = work / f"{spec.name}.so"
    subprocess.run(["gcc", "-std=c99", "-D_DEFAULT_SOURCE", "-Wall", "-Wextra", "-Werror",
                    "-shared", "-fPIC", "-O1", f"-I{headers}", f"-I{HERE}",
                    *[f"-D{d}" for d in spec.defines], "-o", str(lib),
                    str(HERE / spec.source), "-lm"], check=True, capture_output=True, text=True)
    path = out_dir / f"{spec.name}.fmu"
    with zipfile.ZipFile(path, "w") as z:
        z.writestr("modelDescription.xml", model_description(spec))
        z.write(lib, f"binaries/linux64/{spec.name}.so")
    return path


def build_hostile(out_dir: Path, names: tuple[str, ...] | None = None) -> dict[str, Path]:
    """The hostile test FMUs (:data:`HOSTILE`, all or ``names``) built into ``out_dir``."""
    work = out_dir / "build"
    work.mkdir(parents=True, exist_ok=True)
    return {name: build(HOSTILE[name], out_dir, work) for name in names or HOSTILE}


def build_all(out_dir: Path) -> dict[str, Path]:
    """Every test FMU built into ``out_dir``: name -> path."""
    if shutil.which("gcc") is None:
        raise FileNotFoundError("gcc is not installed")
    work = out_dir / "build"
    work.mkdir(parents=True, exist_ok=True)
    return {spec.name: build(spec, out_dir, work) for spec in SPECS}
