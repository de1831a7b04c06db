"""Static checks: read from the FMU file, nothing loaded (fmpy validation, variables,
units, model structure, default experiment, capabilities)."""

from __future__ import annotations

from pathlib import Path
from xml.etree import ElementTree

from cosim.interop.compliance.common import (
    CONVENTION,
    STATIC_CHECKS,
    WARNING,
    Problem,
    _num,
    _read_xml,
    classify,
    skipped,
)

# FMI 2.0 Table (sec. 2.2.7): legal causality for each variability
_LEGAL = {
    "constant": {"output", "local"},
    "fixed": {"parameter", "calculatedParameter", "local"},
    "tunable": {"parameter", "calculatedParameter", "local"},
    "discrete": {"input", "output", "local"},
    "continuous": {"input", "output", "local", "independent"},
}


def _allowed_initial(causality: str, variability: str) -> tuple[set[str | None], str | None]:
    """Allowed ``initial`` values (None = attribute absent) and the default (sec. 2.2.7)."""
    if variability == "constant":
        return {None, "exact"}, "exact"
    if causality == "parameter":
        return {None, "exact"}, "exact"
    if causality == "calculatedParameter":
        return {None, "approx", "calculated"}, "calculated"
    if causality in ("input", "independent"):
        return {None}, None
    if variability in ("fixed", "tunable"):  # local
        return {None, "approx", "calculated"}, "calculated"
    return {None, "exact", "approx", "calculated"}, "calculated"  # output / local



def check_model_description(path: str | Path, strict: bool = True) -> list[Problem]:
    """Static checks on the FMU file, each naming its FMI 2.0.4 clause. ``strict`` keeps project
    conventions (every Real has a unit, outputs declare dependencies explicitly, default
    experiment has a step size) errors; otherwise they, and what the standard only
    recommends, are warnings."""
    return classify(_static_checks(Path(path)), strict)


def _static_checks(path: Path) -> list[Problem]:
    from fmpy import read_model_description
    from fmpy.validation import validate_fmu

    path = Path(path)
    problems: list[Problem] = []
    try:
        messages = validate_fmu(str(path))
    except Exception as err:  # a broken archive or XML
        return skipped(STATIC_CHECKS, "the archive could not be read",
                       [Problem("fmpy-validation", f"cannot be validated: {err}")])
    problems += [Problem("fmpy-validation", str(m).strip()) for m in messages]
    try:
        root = _read_xml(path)
        md = read_model_description(str(path), validate=False)
    except Exception as err:
        return skipped(STATIC_CHECKS, "modelDescription.xml could not be read",
                       [*problems, Problem("variables", f"modelDescription.xml unreadable: "
                                                        f"{err}")])
    if root.get("fmiVersion") != "2.0":
        problems.append(Problem("capabilities", f"fmiVersion {root.get('fmiVersion')!r}, "
                                                "these checks are for FMI 2.0"))
        return skipped(STATIC_CHECKS, "not an FMI 2.0 FMU", problems)

    # variables: causality/variability/initial, start and min/max
    xml_vars = root.find("ModelVariables")
    xml_list = list(xml_vars) if xml_vars is not None else []
    declared_units = {u.get("name") for u in root.iter("Unit")}
    type_units = {t.get("name"): (t[0].get("unit") if len(t) else None)
                  for t in root.iter("SimpleType")}
    used_units: set[str] = set(u for u in type_units.values() if u)
    for sv in xml_list:
        name = sv.get("name")
        causality = sv.get("causality", "local")
        variability = sv.get("variability", "continuous")
        initial = sv.get("initial")
        type_node = sv[0] if len(sv) else None
        if type_node is None:
            problems.append(Problem("variables", f"{name}: no type element"))
            continue
        kind = type_node.tag
        if variability not in _LEGAL:
            problems.append(Problem("variables", f"{name}: unknown variability {variability!r}"))
            continue
        if causality not in _LEGAL[variability]:
            problems.append(Problem("variables", f"{name}: causality {causality!r} with "
                                                 f"variability {variability!r} is not allowed"))
        if kind != "Real" and variability == "continuous":
            problems.append(Problem("variables", f"{name}: a {kind} cannot be continuous"))
        allowed, default = _allowed_initial(causality, variability)
        if initial not in allowed:
            problems.append(Problem("variables", f"{name}: initial={initial!r} not allowed for "
                                                 f"{causality}/{variability}"))
        effective = initial or default
        start = type_node.get("start")
        if (effective in ("exact", "approx") or causality == "input") and start is None:
            problems.append(Problem("variables", f"{name}: a start value is required "
                                                 f"({causality}, initial={effective})"))
        if (effective == "calculated" or causality == "independent") and start is not None:
            problems.append(Problem("variables", f"{name}: a start value is not allowed "
                                                 f"({causality}, initial={effective})"))
        lo, hi, st = _num(type_node.get("min")), _num(type_node.get("max")), _num(start)
        if lo is not None and hi is not None and lo > hi:
            problems.append(Problem("variables", f"{name}: min {lo} > max {hi}"))
        if st is not None and (lo is not None and st < lo or hi is not None and st > hi):
            problems.append(Problem("variables", f"{name}: start {st} outside [{lo}, {hi}]"))
        if kind == "Real":
            unit = type_node.get("unit") or type_units.get(type_node.get("declaredType") or "")
            if unit:
                used_units.add(unit)
                if unit not in declared_units:
                    problems.append(Problem("units", f"{name}: unit {unit!r} is not declared "
                                                     "in UnitDefinitions"))
            elif causality != "independent":
                problems.append(Problem("units", f"{name}: Real variable without a unit "
                                        "(optional in FMI 2.0.4 2.2.7)",
                                        requirement=CONVENTION))
    for unit in sorted(declared_units - used_units):
        problems.append(Problem("units", f"unit {unit!r} declared but not used", WARNING))

    # model structure: outputs with explicit dependencies on inputs only
    by_index = {i + 1: sv for i, sv in enumerate(xml_list)}
    outputs = {sv.get("name") for sv in xml_list if sv.get("causality") == "output"}
    structure = root.find("ModelStructure")
    listed: dict[str, ElementTree.Element] = {}
    if structure is not None and structure.find("Outputs") is not None:
        for unk in structure.find("Outputs"):
            sv = by_index.get(int(unk.get("index", "0")))
            if sv is None:
                problems.append(Problem("model-structure", f"Outputs: bad index "
                                                           f"{unk.get('index')}"))
                continue
            listed[sv.get("name")] = unk
    for name in sorted(outputs - set(listed)):
        problems.append(Problem("model-structure", f"output {name} is not listed in "
                                                   "ModelStructure/Outputs"))
    for name, unk in listed.items():
        if name not in outputs:
            problems.append(Problem("model-structure", f"{name} in Outputs is not an output"))
        deps = unk.get("dependencies")
        if deps is None:
            problems.append(Problem("model-structure", f"output {name}: no dependencies "
                                    "attribute (means 'depends on everything')",
                                    requirement=CONVENTION))
            continue
        for token in deps.split():
            dep = by_index.get(int(token))
            if dep is None:
                problems.append(Problem("model-structure", f"output {name}: dependency index "
                                                           f"{token} does not exist"))
            elif dep.get("causality") not in ("input", "local", "output"):
                problems.append(Problem("model-structure", f"output {name} depends on "
                                        f"{dep.get('name')} ({dep.get('causality')}); only "
                                        "inputs and states may be listed"))

    # default experiment and capabilities
    de = md.defaultExperiment
    if de is None:
        problems.append(Problem("default-experiment", "no DefaultExperiment element"))
    else:
        if de.stopTime is None:
            problems.append(Problem("default-experiment", "DefaultExperiment has no stopTime",
                                    requirement=CONVENTION))
        if de.stepSize is None:
            problems.append(Problem("default-experiment", "DefaultExperiment has no stepSize",
                                    requirement=CONVENTION))
    cs = md.coSimulation
    if cs is None:
        problems.append(Problem("capabilities", "not a co-simulation FMU"))
    else:
        for flag in ("canHandleVariableCommunicationStepSize", "canGetAndSetFMUstate",
                     "canSerializeFMUstate"):
            if not getattr(cs, flag):
                problems.append(Problem("capabilities", f"{flag} is false; the related "
                                                        "checks are skipped",
                                                        requirement=CONVENTION))
    return problems

