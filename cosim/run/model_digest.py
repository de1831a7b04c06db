"""A comparable digest of a modelDescription.xml (what a user of the FMU sees of it)."""

from __future__ import annotations

from typing import Any
from xml.etree import ElementTree


def digest_model_description(xml: bytes | str) -> dict[str, Any]:
    """Variables by name (causality, variability, initial, description, type, unit, min, max,
    start), default experiment, unit names and output dependencies by name."""
    root = ElementTree.fromstring(xml)
    variables: dict[str, dict[str, str]] = {}
    names: dict[str, str] = {}
    for i, sv in enumerate(root.find("ModelVariables")):
        names[str(i + 1)] = sv.get("name")
        typ = sv[0]
        entry = {k: sv.get(k) for k in ("causality", "variability", "initial", "description")}
        entry["type"] = typ.tag
        entry.update({k: typ.get(k) for k in ("unit", "min", "max", "start")
                      if typ.get(k) is not None})
        variables[sv.get("name")] = entry
    units = root.find("UnitDefinitions")
    experiment = root.find("DefaultExperiment")
    outputs = root.find("ModelStructure/Outputs")
    dependencies = {}
    for unknown in (outputs if outputs is not None else []):
        deps = (unknown.get("dependencies") or "").split()
        dependencies[names[unknown.get("index")]] = sorted(names[d] for d in deps)
    return {
        "description": root.get("description"),
        "default_experiment": dict(experiment.attrib) if experiment is not None else {},
        "units": sorted(u.get("name") for u in units) if units is not None else [],
        "variables": variables,
        "output_dependencies": dependencies,
    }
