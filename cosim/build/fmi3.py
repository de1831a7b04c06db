"""FMI 3.0 co-simulation builds of our FMUs, derived from their FMI 2.0 builds.

An FMI 3 FMU holds the same resources (the Python bundle, pythonfmu's slave module) as its FMI
2 twin, and in ``binaries/x86_64-linux/``:

* ``<id>.so``: the FMI 3.0 front (``cosim/fmu/front/fmi3_front.c``, compiled once per
  process) linked with the dlopen backend (``ato_backend_fmi2dl.c``, compiled for the FMU's
  event-time value reference);
* ``<id>_fmi2.so``: the FMI 2 shim (``cosim/fmu/pythonfmu_shim.c``) the backend loads;
* ``<id>_fmi2_pythonfmu.so``: pythonfmu's binary the shim loads.

Its modelDescription.xml is the FMI 2 one (itself written from the core's declarations by
:meth:`cosim.fmu.slave.CoreSlave.to_xml`) in FMI 3.0 terms: the same variable names, value
references, units, ranges, starts, descriptions and dependencies, plus the independent variable
``time`` that FMI 3.0 requires (value reference :data:`TIME_VR`); ``instantiationToken`` is
the FMI 2 ``guid``; a model with a ``next_event_time`` output (the sampled and self-triggered
controllers, :data:`cosim.fmu.slave.CONTROLLER_TIMING_VARS`) declares ``hasEventMode`` and
``mightReturnEarlyFromDoStep`` (the front announces that output as ``nextEventTime`` and
returns early there when allowed); every model declares
``canHandleVariableCommunicationStepSize`` as its FMI 2 twin does. The win64 binary is not
carried over: the front is compiled here, for x86-64 Linux only. The native FMUs' FMI 3 builds
(:mod:`cosim.build.native`) link the same front with a C model instead, for Linux and
Windows, with :func:`model_description` of their FMI 2 modelDescription.

A clocked build (:func:`clocked`, ``cosim build --fmi 3 --clock periodic|countdown``) of a
sampled or self-triggered controller is its FMI 3 build with one input Clock ``sample``
(value reference :data:`CLOCK_VR`) that activates its events (FMI 3.0 sec. 2.2.8) in place of
``nextEventTime``: ``periodic``, intervalVariability ``fixed``, interval its parameter
``sample_time`` (fmi3GetIntervalDecimal in Initialization Mode), shift 0; ``countdown``: the
FMU gives the time to its next event in Event Mode (self-triggered controllers). Its
outputs are clocked by it (``clocks``); it does not return early from doStep (the importer
steps to the ticks). The front is compiled with the Clock's settings
(``front/fmi3_front.c``, ATO_CLOCK_VR); the model is unchanged.

A clocked build has one of two interfaces (``--interface``, :data:`INTERFACES`): ``cs``,
Co-Simulation in Event Mode (FMI 3.0 sec. 2.2.8.2: the importer ticks the Clock with
fmi3SetClock in Event Mode), or ``se``, Scheduled Execution (FMI 3.0 chap. 5: the Clock is the
input Clock of the model's one partition, which the importer runs with
fmi3ActivateModelPartition at its ticks; the Clock declares ``priority`` 0, sec. 2.4.4; the
countdown Clock's first tick is at the start time, sec. 2.2.8.2 (countdown Clock); the front's
ATO_SCHEDULED).
The ``ScheduledExecution`` element keeps the attributes every interface has (sec. 2.4.2,
fmi3InterfaceType) and offers no FMU state.
"""

from __future__ import annotations

import atexit
import shutil
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path
from xml.etree import ElementTree as ET

FRONT_DIR = Path(__file__).resolve().parents[1] / "fmu" / "front"  # the FMU layer's C fronts
FRONT_SOURCES = (FRONT_DIR / "fmi3_front.c", FRONT_DIR / "ato_backend_fmi2dl.c")
FRONT_HEADER = FRONT_DIR / "ato_backend.h"
PLATFORM = "x86_64-linux"
EVENT_TIME_OUTPUT = "next_event_time"  # the controllers' announced next event (slave.py)
TIME_VR = 2147483647  # the independent variable `time`: ATO_TIME_VR of front/ato_backend.h
FMI2_SUFFIX = "_fmi2"  # <id>_fmi2.so: the FMI 2 binary (shim) the front's backend loads
CLOCK_VR = TIME_VR - 1  # the input Clock `sample` of a clocked build
CLOCK_NAME = "sample"
CLOCK_VARIABILITY = {"periodic": "fixed", "countdown": "countdown"}  # build -> FMI 3 attribute
SAMPLE_TIME = "sample_time"  # the controllers' sample time parameter (s): the periodic interval
# clocked build's interface -> its modelDescription element: Co-Simulation (Event Mode) or
# Scheduled Execution (FMI 3.0 chap. 5)
INTERFACES = {"cs": "CoSimulation", "se": "ScheduledExecution"}
# the fmi3InterfaceType attributes a ScheduledExecution element keeps (FMI 3.0 sec. 2.4.2)
_SCHEDULED_ATTRIBUTES = ("modelIdentifier", "needsExecutionTool",
                         "canBeInstantiatedOnlyOncePerProcess")

_TYPES = {"Real": "Float64", "Integer": "Int32", "Boolean": "Boolean", "String": "String",
          "Enumeration": "Enumeration"}
# FMI 2 CoSimulation attributes with the same meaning in FMI 3.0 (sec. 4.4), renamed
_COSIM_ATTRIBUTES = {
    "modelIdentifier": "modelIdentifier",
    "needsExecutionTool": "needsExecutionTool",
    "canBeInstantiatedOnlyOncePerProcess": "canBeInstantiatedOnlyOncePerProcess",
    "canGetAndSetFMUstate": "canGetAndSetFMUState",
    "canSerializeFMUstate": "canSerializeFMUState",
    "canHandleVariableCommunicationStepSize": "canHandleVariableCommunicationStepSize",
}


class Fmi3BuildError(RuntimeError):
    """The FMI 3 build cannot be made here (no gcc, not Linux, compile error)."""


def model_description(fmi2_xml: bytes) -> tuple[bytes, int]:
    """The FMI 3.0 modelDescription.xml of an FMU whose FMI 2.0 one is ``fmi2_xml``, and the
    value reference of its event-time output (-1: none)."""
    src = ET.fromstring(fmi2_xml)
    if src.get("fmiVersion") != "2.0":
        raise ValueError(f"not an FMI 2.0 modelDescription (fmiVersion={src.get('fmiVersion')})")
    variables = src.find("ModelVariables")
    scalars = list(variables) if variables is not None else []
    event_vr = next((int(sv.get("valueReference")) for sv in scalars
                     if sv.get("name") == EVENT_TIME_OUTPUT and sv.get("causality") == "output"),
                    -1)
    root_attrib = {"fmiVersion": "3.0"}
    for key in ("modelName", "description", "author", "version", "copyright", "license",
                "generationTool", "generationDateAndTime", "variableNamingConvention"):
        if src.get(key) is not None:
            root_attrib[key] = src.get(key)
    root_attrib["instantiationToken"] = src.get("guid", "")
    root = ET.Element("fmiModelDescription", root_attrib)

    cs_src = src.find("CoSimulation")
    if cs_src is None:
        raise ValueError("the FMI 2.0 modelDescription has no CoSimulation element")
    cs = {new: cs_src.get(old) for old, new in _COSIM_ATTRIBUTES.items()
          if cs_src.get(old) is not None}
    cs["providesIntermediateUpdate"] = "false"
    if event_vr >= 0:
        cs["hasEventMode"] = "true"
        cs["mightReturnEarlyFromDoStep"] = "true"
    ET.SubElement(root, "CoSimulation", cs)

    units = src.find("UnitDefinitions")  # identical in FMI 3.0 (sec. 2.4.3, UnitDefinitions)
    if units is None:
        units = ET.Element("UnitDefinitions")
    if not any(u.get("name") == "s" for u in units):  # the unit of `time`
        ET.SubElement(ET.SubElement(units, "Unit", {"name": "s"}), "BaseUnit", {"s": "1"})
    root.append(units)
    categories = src.find("LogCategories")
    if categories is not None:
        node = ET.SubElement(root, "LogCategories")
        for c in categories:
            attrib = dict(c.attrib)
            if "description" in attrib:
                attrib["description"] = attrib["description"].replace("fmi2", "fmi3")
            ET.SubElement(node, "Category", attrib)
    experiment = src.find("DefaultExperiment")
    if experiment is not None:
        root.append(experiment)

    node = ET.SubElement(root, "ModelVariables")
    # FMI 3.0 sec. 2.4.7.4 (causality independent): exactly one independent variable; the
    # front answers it
    ET.SubElement(node, "Float64", {"name": "time", "valueReference": str(TIME_VR),
                                    "description": "simulation time", "causality": "independent",
                                    "variability": "continuous", "unit": "s"})
    vr_of_index: dict[int, str] = {}
    for index, sv in enumerate(scalars, start=1):
        vr_of_index[index] = sv.get("valueReference")
        typed = sv[0]
        kind = _TYPES.get(typed.tag)
        if kind is None or kind == "Enumeration":
            raise ValueError(f"variable {sv.get('name')}: type {typed.tag} has no FMI 3 mapping "
                             "here")
        attrib = {k: sv.get(k) for k in ("name", "valueReference", "description", "causality",
                                         "variability", "initial") if sv.get(k) is not None}
        start = typed.get("start")
        for k in ("unit", "min", "max", "nominal", "quantity", "displayUnit"):
            if typed.get(k) is not None:
                attrib[k] = typed.get(k)
        if start is not None and kind != "String":
            attrib["start"] = start
        var = ET.SubElement(node, kind, attrib)
        if start is not None and kind == "String":
            ET.SubElement(var, "Start", {"value": start})

    structure = ET.SubElement(root, "ModelStructure")
    src_structure = src.find("ModelStructure")
    if src_structure is not None:
        for tag, new in (("Outputs", "Output"), ("InitialUnknowns", "InitialUnknown")):
            group = src_structure.find(tag)
            for unknown in group if group is not None else []:
                attrib = {"valueReference": vr_of_index[int(unknown.get("index"))]}
                deps = unknown.get("dependencies")
                if deps is not None:
                    attrib["dependencies"] = " ".join(vr_of_index[int(i)] for i in deps.split())
                ET.SubElement(structure, new, attrib)
    ET.indent(root, "\t")
    text = ET.tostring(root, encoding="unicode")
    return ('<?xml version="1.0" encoding="UTF-8"?>\n' + text + "\n").encode(), event_vr


_front_cache: dict[int, Path] = {}
_front_dir: list[Path] = []


def _gcc(args: list[str], what: str) -> None:
    done = subprocess.run(args, capture_output=True, text=True)
    if done.returncode != 0:
        raise Fmi3BuildError(f"gcc failed on {what}: {done.stderr.strip()[-2000:]}")


def front_binary(event_vr: int, defines: tuple[str, ...] = ()) -> Path:
    """The front (compiled with the C macros ``defines``, ``NAME=value``: a clocked build's)
    linked with its dlopen backend for event-time value reference ``event_vr`` (-1: none):
    each front compiled once per process, the small backend once per value reference."""
    key = (event_vr, defines)
    if key in _front_cache:
        return _front_cache[key]
    gcc = shutil.which("gcc")
    if not sys.platform.startswith("linux"):
        raise Fmi3BuildError(f"FMI 3 builds are made on Linux only (this is {sys.platform})")
    if gcc is None:
        raise Fmi3BuildError("FMI 3 builds need gcc to compile the front "
                             f"({FRONT_SOURCES[0]}); gcc not found")
    import fmpy

    flags = ["-fPIC", "-O2", "-std=c99", "-fvisibility=hidden", "-Wall",
             f"-I{Path(fmpy.__file__).parent / 'c-code'}", f"-I{FRONT_DIR}"]
    if not _front_dir:
        _front_dir.append(Path(tempfile.mkdtemp(prefix="atocosim_front_")))
        atexit.register(shutil.rmtree, _front_dir[0], True)
    folder = _front_dir[0]
    variant = "_".join(d.replace("=", "") for d in defines)
    front = folder / f"fmi3_front{'_' + variant if variant else ''}.o"
    if not front.is_file():
        _gcc([gcc, "-c", *flags, *(f"-D{d}" for d in defines), "-o", str(front),
              str(FRONT_SOURCES[0])], "the FMI 3 front")
    label = event_vr if event_vr >= 0 else "none"
    backend = folder / f"backend_{label}.o"
    _gcc([gcc, "-c", *flags, f"-DATO_EVENT_TIME_VR={int(event_vr)}", "-o", str(backend),
          str(FRONT_SOURCES[1])], "the FMI 3 front's backend")
    out = folder / f"fmi3_front_{label}{'_' + variant if variant else ''}.so"
    _gcc([gcc, "-shared", "-o", str(out), str(front), str(backend), "-ldl", "-lm"],
         "linking the FMI 3 front")
    _front_cache[key] = out
    return out


def clocked_description(fmi3_xml: bytes, clock: str,
                        interface: str = "cs") -> tuple[bytes, tuple[str, ...]]:
    """The modelDescription.xml of the ``clock`` (``periodic`` or ``countdown``) build with
    ``interface`` (:data:`INTERFACES`) of the FMI 3 controller whose modelDescription is
    ``fmi3_xml``, and the front's C macros for it; a model that is no sampled controller (no
    ``next_event_time`` output, or no ``sample_time`` parameter for a periodic Clock) is a
    ValueError."""
    if clock not in CLOCK_VARIABILITY:
        raise ValueError(f"clock {clock!r}: expected one of {list(CLOCK_VARIABILITY)}")
    if interface not in INTERFACES:
        raise ValueError(f"interface {interface!r}: expected one of {list(INTERFACES)}")
    root = ET.fromstring(fmi3_xml)
    variables = root.find("ModelVariables")
    by_name = {v.get("name"): v for v in variables}
    event = by_name.get(EVENT_TIME_OUTPUT)
    if event is None or event.get("causality") != "output":
        raise ValueError(f"{root.get('modelName')}: a {clock} Clock activates a sampled "
                         f"controller's events: this model has no {EVENT_TIME_OUTPUT} output")
    defines = [f"ATO_CLOCK_VR={CLOCK_VR}L", f"ATO_CLOCK_COUNTDOWN={int(clock == 'countdown')}"]
    if clock == "periodic":
        sample = by_name.get(SAMPLE_TIME)
        if sample is None or sample.get("causality") != "parameter":
            raise ValueError(f"{root.get('modelName')}: a periodic Clock ticks at the "
                             f"parameter {SAMPLE_TIME}, which this model does not have")
        defines.append(f"ATO_SAMPLE_TIME_VR={int(sample.get('valueReference'))}L")
    clocked_vrs = set()
    for v in variables:
        if v.get("causality") == "output" and v.get("variability") == "discrete":
            v.set("clocks", str(CLOCK_VR))
            clocked_vrs.add(v.get("valueReference"))
    structure = root.find("ModelStructure")
    for unknown in structure.findall("InitialUnknown"):  # not clocked ones (sec. 2.4.8)
        if unknown.get("valueReference") in clocked_vrs:
            structure.remove(unknown)
    cs = root.find("CoSimulation")
    cs.set("mightReturnEarlyFromDoStep", "false")  # ticks, not returns
    declared = {"name": CLOCK_NAME, "valueReference": str(CLOCK_VR),
                        "description": "activates the controller's events (its sample instants)",
                        "causality": "input", "variability": "discrete",
                        "intervalVariability": CLOCK_VARIABILITY[clock]}
    if interface == "se":
        defines.append("ATO_SCHEDULED=1")
        scheduled = ET.Element(INTERFACES[interface], {k: cs.get(k) for k in _SCHEDULED_ATTRIBUTES
                                                       if cs.get(k) is not None})
        root.insert(list(root).index(cs), scheduled)
        root.remove(cs)
        declared["priority"] = "0"  # its one partition (sec. 2.4.4)
    position = list(variables).index(by_name["time"]) + 1
    variables.insert(position, ET.Element("Clock", declared))
    ET.indent(root, "\t")
    text = ET.tostring(root, encoding="unicode")
    return ('<?xml version="1.0" encoding="UTF-8"?>\n' + text + "\n").encode(), tuple(defines)


def clocked(fmi3_fmu: Path, clock: str, out: Path, interface: str = "cs") -> Path:
    """Write the ``clock`` build with ``interface`` ``out`` (:func:`clocked_description`) of the
    FMI 3 build ``fmi3_fmu`` of a Python controller: its modelDescription and front replaced."""
    with zipfile.ZipFile(fmi3_fmu) as zin:
        xml = zin.read("modelDescription.xml")
        md, defines = clocked_description(xml, clock, interface)
        identifier = ET.fromstring(xml).find("CoSimulation").get("modelIdentifier")
        event_vr = int(next(v.get("valueReference") for v in ET.fromstring(xml).iter()
                            if v.get("name") == EVENT_TIME_OUTPUT))
        front = front_binary(event_vr, defines)
        target = f"binaries/{PLATFORM}/{identifier}.so"
        out.parent.mkdir(parents=True, exist_ok=True)
        with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as zout:
            for item in zin.infolist():
                data = (md if item.filename == "modelDescription.xml" else
                        front.read_bytes() if item.filename == target else zin.read(item))
                zout.writestr(item, data)
    return out


def package(fmi2_fmu: Path, identifier: str, out: Path) -> Path:
    """Write the FMI 3 FMU ``out`` from the FMI 2 FMU ``fmi2_fmu`` (built with the shim)."""
    shim = f"binaries/linux64/{identifier}.so"
    inner = f"binaries/linux64/{identifier}_pythonfmu.so"
    target = f"binaries/{PLATFORM}/{identifier}"
    with zipfile.ZipFile(fmi2_fmu) as zin:
        names = set(zin.namelist())
        if shim not in names or inner not in names:
            raise Fmi3BuildError(f"{fmi2_fmu}: the FMI 3 build needs the FMI 2 build's shim "
                                 f"({shim}) and pythonfmu's binary ({inner}); see the warning "
                                 "of the FMI 2 build")
        md, event_vr = model_description(zin.read("modelDescription.xml"))
        front = front_binary(event_vr)
        out.parent.mkdir(parents=True, exist_ok=True)
        with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as zout:
            for item in zin.infolist():
                name = item.filename
                if name.startswith("binaries/"):
                    continue
                data = md if name == "modelDescription.xml" else zin.read(item)
                zout.writestr(item, data)
            stamp = zin.getinfo(shim).date_time
            attr = zin.getinfo(shim).external_attr
            for name, payload in ((f"{target}.so", front.read_bytes()),
                                  (f"{target}{FMI2_SUFFIX}.so", zin.read(shim)),
                                  (f"{target}{FMI2_SUFFIX}_pythonfmu.so", zin.read(inner))):
                info = zipfile.ZipInfo(name, date_time=stamp)
                info.compress_type = zipfile.ZIP_DEFLATED
                info.external_attr = attr
                zout.writestr(info, payload)
    return out


def builder_files() -> list[Path]:
    """The files an FMI 3 build depends on besides the FMI 2 build's."""
    return [Path(__file__).resolve(), *FRONT_SOURCES, FRONT_HEADER,
            FRONT_DIR / "instance_registry.h"]

