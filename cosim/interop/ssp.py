"""Export a scenario as an SSP 1.0 System Structure Package (``cosim export --ssp``).

The archive holds ``SystemStructure.ssd`` and the scenario's FMUs under ``resources/``:

* one ``ssd:Component`` per scenario FMU (``source="resources/<file>.fmu"``) with a connector
  for each of its inputs and outputs and for each bound parameter, typed and with units;
* the scenario's parameter values (and ``sample_time``, and constant inputs) as an inline
  ``ssv:ParameterSet`` in the component's ``ssd:ParameterBindings``;
* one ``ssd:Connection`` per scenario connection (no ``ssd:Connections`` element without one:
  the schema requires at least one child);
* connectors and parameter values of every FMI 2.0 type; an Enumeration's items go into
  ``ssd:Enumerations`` and its values are written by item name;
* ``ssd:Units`` copied from the FMUs' UnitDefinitions;
* ``ssd:DefaultExperiment`` with the scenario's start and stop time, and the base step as the
  Open Simulation Platform annotation ``osp:FixedStepAlgorithm`` (read by libcosim).

The result passes ``fmpy.ssp.ssd.read_ssd(path, validate=True)`` (the SSP 1.0 schema) and runs
in libcosim (``CosimExecution.from_ssp_file``) with the results of our master's ``jacobi``
mode. Step-size hints are not written: every FMU steps at the base step, as in our master.
"""

from __future__ import annotations

import zipfile
from pathlib import Path
from typing import Any
from xml.etree.ElementTree import Element, SubElement, indent, register_namespace, tostring

from cosim.interop.libcosim import ENUMERATION_REASON, enumerations_used
from cosim.run.dependencies import order_connections, output_dependencies
from cosim.run.fmi_types import enumeration_items, to_fmi
from cosim.run.scenario import (
    Scenario,
    ScenarioError,
    check_against_fmus,
    check_timing,
    load_scenario,
)
from cosim.run.simulate import ensure_built

SSD = "http://ssp-standard.org/SSP1/SystemStructureDescription"
SSC = "http://ssp-standard.org/SSP1/SystemStructureCommon"
SSV = "http://ssp-standard.org/SSP1/SystemStructureParameterValues"
OSP = "http://opensimulationplatform.com/SSP/OSPAnnotations"
ATO = "urn:ato-cosim:ssp"  # our annotation: a component's max_step (s)
ANNOTATION_TYPE = "org.ato-cosim.timing"
for _prefix, _uri in (("ssd", SSD), ("ssc", SSC), ("ssv", SSV), ("osp", OSP), ("ato", ATO)):
    register_namespace(_prefix, _uri)

_BASE_UNIT_KEYS = ("kg", "m", "s", "A", "K", "mol", "cd", "rad")


def _q(ns: str, tag: str) -> str:
    return f"{{{ns}}}{tag}"


def _format(value: Any, kind: str) -> str:
    if kind == "Real":
        return repr(float(value))
    if kind == "Integer":
        return str(int(value))
    if kind == "Boolean":
        return "true" if value else "false"
    return str(value)


def _enumeration_name(v: Any) -> str:
    return v.declaredType.name if v.declaredType is not None else v.name


def _component(system_elements: Element, name: str, source: str, md: Any,
               values: dict[str, Any], connected: set[str],
               enumerations: dict[str, dict[str, int]]) -> set[str]:
    """Add one ``ssd:Component``; returns the units its connectors use and collects the
    Enumeration types in ``enumerations`` (name -> items)."""
    comp = SubElement(system_elements, _q(SSD, "Component"), {
        "name": name, "type": "application/x-fmu-sharedlibrary", "source": source})
    connectors = SubElement(comp, _q(SSD, "Connectors"))
    variables = {v.name: v for v in md.modelVariables}
    units: set[str] = set()
    for v in md.modelVariables:
        if v.causality not in ("input", "output") and v.name not in values:
            continue
        if v.type not in ("Real", "Integer", "Boolean", "String", "Enumeration"):
            if v.name in connected or v.name in values:
                raise ValueError(f"{name}: {v.name} has type {v.type}, which SSP 1.0 "
                                 f"connectors cannot carry ({source})")
            continue
        kind = v.causality if v.causality in ("input", "output") else "parameter"
        conn = SubElement(connectors, _q(SSD, "Connector"), {"name": v.name, "kind": kind})
        attrib = {}
        if v.type == "Real" and v.unit:
            attrib["unit"] = v.unit
            units.add(v.unit)
        if v.type == "Enumeration":
            attrib["name"] = _enumeration_name(v)
            enumerations[attrib["name"]] = enumeration_items(v)
        SubElement(conn, _q(SSC, v.type), attrib)
    missing = sorted(n for n in connected if n not in variables)
    if missing:
        raise ValueError(f"{name}: no variables {missing} in {source}")
    if values:
        bindings = SubElement(comp, _q(SSD, "ParameterBindings"))
        binding = SubElement(bindings, _q(SSD, "ParameterBinding"))
        pvalues = SubElement(binding, _q(SSD, "ParameterValues"))
        pset = SubElement(pvalues, _q(SSV, "ParameterSet"), {"version": "1.0", "name": name})
        params = SubElement(pset, _q(SSV, "Parameters"))
        for pname, value in values.items():
            if pname not in variables:
                raise ValueError(f"{name}: no variable {pname!r} in {source}")
            v = variables[pname]
            p = SubElement(params, _q(SSV, "Parameter"), {"name": pname})
            if v.type == "Enumeration":  # by item name (SSP 1.0 ssv:Enumeration)
                items = enumeration_items(v)
                number = to_fmi("Enumeration", value, items)
                item = next(n for n, k in items.items() if k == number)
                SubElement(p, _q(SSV, "Enumeration"), {"value": item,
                                                       "name": _enumeration_name(v)})
            else:
                SubElement(p, _q(SSV, v.type), {"value": _format(value, v.type)})
    return units


def build_ssd(sc: Scenario, sources: dict[str, str]) -> Element:
    """The ``SystemStructureDescription`` element of a scenario (``sources``: component ->
    path of its FMU inside the package)."""
    from fmpy import read_model_description

    root = Element(_q(SSD, "SystemStructureDescription"), {"version": "1.0", "name": sc.name})
    system = SubElement(root, _q(SSD, "System"), {"name": sc.name,
                                                 "description": sc.description or sc.name})
    elements = SubElement(system, _q(SSD, "Elements"))
    unit_defs: dict[str, Any] = {}
    used_units: set[str] = set()
    enumerations: dict[str, dict[str, int]] = {}
    for comp in sc.components.values():
        md = read_model_description(str(comp.fmu_path))
        unit_defs.update({u.name: u for u in md.unitDefinitions})
        names = {v.name for v in md.modelVariables}
        values = dict(comp.parameters)
        if comp.sample_time is not None and "sample_time" in names:
            values.setdefault("sample_time", comp.sample_time)
        values.update(comp.inputs)
        connected = ({c.src_var for c in sc.connections if c.src == comp.name}
                     | {c.dst_var for c in sc.connections if c.dst == comp.name})
        used_units |= _component(elements, comp.name, sources[comp.name], md, values, connected,
                                 enumerations)
        if comp.max_step is not None:  # SSP 1.0 has no such field: an annotation keeps it
            note = SubElement(SubElement(elements[-1], _q(SSD, "Annotations")),
                              _q(SSC, "Annotation"), {"type": ANNOTATION_TYPE})
            SubElement(note, _q(ATO, "Timing"), {"maxStep": repr(float(comp.max_step))})
    if sc.connections:  # an empty ssd:Connections violates the schema
        connections = SubElement(system, _q(SSD, "Connections"))
    for c in sc.connections:
        SubElement(connections, _q(SSD, "Connection"), {
            "startElement": c.src, "startConnector": c.src_var,
            "endElement": c.dst, "endConnector": c.dst_var})
    if enumerations:
        enums = SubElement(root, _q(SSD, "Enumerations"))
        for ename, items in sorted(enumerations.items()):
            enum = SubElement(enums, _q(SSC, "Enumeration"), {"name": ename})
            for item, number in items.items():
                SubElement(enum, _q(SSC, "Item"), {"name": item, "value": str(number)})
    if used_units:
        units = SubElement(root, _q(SSD, "Units"))
        for name in sorted(used_units):
            unit = SubElement(units, _q(SSC, "Unit"), {"name": name})
            base = unit_defs[name].baseUnit if name in unit_defs else None
            attrib = {}
            if base is not None:
                attrib = {k: str(getattr(base, k)) for k in _BASE_UNIT_KEYS if getattr(base, k)}
                if base.factor != 1.0:
                    attrib["factor"] = repr(float(base.factor))
                if base.offset:
                    attrib["offset"] = repr(float(base.offset))
            SubElement(unit, _q(SSC, "BaseUnit"), attrib)
    sim = sc.simulation
    experiment = SubElement(root, _q(SSD, "DefaultExperiment"), {
        "startTime": repr(float(sim.start_time)), "stopTime": repr(float(sim.stop_time))})
    annotations = SubElement(experiment, _q(SSD, "Annotations"))
    annotation = SubElement(annotations, _q(SSC, "Annotation"),
                            {"type": "com.opensimulationplatform"})
    algorithm = SubElement(annotation, _q(OSP, "Algorithm"))
    SubElement(algorithm, _q(OSP, "FixedStepAlgorithm"), {
        "baseStepSize": repr(float(sim.base_step or sim.output_interval))})
    return root


def export_ssp(scenario: str | Path | Scenario, out: str | Path,
               overrides: dict[str, Any] | list[str] | None = None, build: bool = True) -> Path:
    """Write the scenario (with ``overrides``) and its FMUs as an SSP archive at ``out``, after
    checking the scenario against its FMUs as ``cosim run`` does (names, causalities, types,
    ranges, units, unconnected inputs, algebraic loops)."""
    from fmpy import read_model_description

    sc = scenario if isinstance(scenario, Scenario) else load_scenario(scenario, overrides)
    if build:
        ensure_built(sc)
    descriptions = {}
    for comp in sc.components.values():
        if not comp.fmu_path.is_file():
            raise FileNotFoundError(f"{comp.name}: {comp.fmu_path} not found (run cosim build)")
        descriptions[comp.name] = read_model_description(str(comp.fmu_path))
        version = str(descriptions[comp.name].fmiVersion)
        if not version.startswith("2"):
            raise ScenarioError(
                f"{sc.path}: [fmus.{comp.name}] fmu = {comp.fmu!r}: an FMI {version} FMU "
                f"({comp.fmu_path}): SSP 1.0 connectors carry FMI 2.0 types only (ssc:Real, "
                "Integer, Boolean, String, Enumeration) and the SSP importers we target "
                "(libcosim) run FMI 2.0 only, so the export is refused; export the FMI 2.0 "
                "builds ([simulation] fmi_version = 2) or run the scenario with `cosim run`")
    check_against_fmus(sc, descriptions)
    check_timing(sc, descriptions, "jacobi")  # libcosim steps every FMU at the base step
    try:
        order_connections(sc.connections, {n: output_dependencies(md)
                                           for n, md in descriptions.items()},
                          f"{sc.path}: [connections]: ")
    except ValueError as err:
        raise ScenarioError(str(err)) from err
    files: dict[Path, str] = {}
    for comp in sc.components.values():
        if not comp.fmu_path.is_file():
            raise FileNotFoundError(f"{comp.name}: {comp.fmu_path} not found (run cosim build)")
        if comp.fmu_path not in files:
            stem, n = comp.fmu_path.stem, 1
            target = f"resources/{stem}.fmu"
            while target in files.values():
                n += 1
                target = f"resources/{stem}_{n}.fmu"
            files[comp.fmu_path] = target
    sources = {c.name: files[c.fmu_path] for c in sc.components.values()}
    root = build_ssd(sc, sources)
    indent(root)
    xml = b'<?xml version="1.0" encoding="UTF-8"?>\n' + tostring(root, encoding="utf-8")
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("SystemStructure.ssd", xml)
        for path, target in files.items():
            z.write(path, target)
    return out


def export_notes(sc: Scenario) -> list[str]:
    """What an SSP 1.0 importer will not honour in the exported scenario: each component's
    ``max_step``, written as an ``org.ato-cosim.timing`` annotation that libcosim ignores; and
    the Enumeration variables the scenario sets or connects, which libcosim cannot run
    (:data:`cosim.interop.libcosim.ENUMERATION_REASON`)."""
    from fmpy import read_model_description

    notes = [f"[fmus.{c.name}] max_step = {c.max_step:g} s is kept as an SSP annotation "
             f"({ANNOTATION_TYPE}); SSP 1.0 has no such field and libcosim ignores it: run the "
             f"SSP with a base step of at most {c.max_step:g} s"
             for c in sc.components.values() if c.max_step is not None]
    enumerations = enumerations_used(sc, {c.name: read_model_description(str(c.fmu_path))
                                          for c in sc.components.values()})
    if enumerations:
        notes.append(f"{', '.join(enumerations)}: written as SSP 1.0 Enumerations (other SSP "
                     f"importers read them), but {ENUMERATION_REASON}")
    return notes
