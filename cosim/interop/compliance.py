"""FMI 2.0 co-simulation compliance checks for any FMU (ours or a third party's).

``check_fmu(path)`` returns a list of :class:`Problem`; ``format_report`` renders it. The
checks are those of issue 5:

* static (read from the file, nothing loaded): fmpy validation; legal causality / variability /
  initial combinations (FMI 2.0 sec. 2.2.7); start values present where required and inside
  min/max; units used are declared and declared units are used; outputs listed in
  ModelStructure/Outputs with an explicit ``dependencies`` attribute naming inputs only;
  default experiment; co-simulation capability flags;
* dynamic (the FMU is loaded and run): the calling sequence instantiate -> setup ->
  initialisation -> doStep* -> terminate -> freeInstance; declared-independent outputs do not
  move when inputs change; fmi2Reset then a rerun is identical; get/set and
  serialize/deserialize FMU state mid-run reproduce the rest of the run exactly (also in a
  fresh instance); variable communication step sizes; two instances in one process stay
  independent; calls in the wrong state, NaN/inf inputs and out-of-range or non-finite
  parameters are rejected (non-OK status or rejected at initialisation) with a logged message.
  The expected status is fmi2Error; fmi2Fatal is an error too (it declares every instance of
  the FMU unusable, so a master cannot recover; plain pythonfmu 0.7 binaries return it for any
  Python exception, ours go through a shim that returns fmi2Error, see ``cosim/fmu/build.py``).

The dynamic checks run in a worker subprocess (``python -m cosim.interop.compliance``), so an
FMU that crashes or hangs the host is reported as a problem of the check it was in, and the
worker is restarted for the remaining checks. ``check_together(paths)`` loads several FMUs in
one process and checks that they do not disturb each other (pythonfmu FMUs share one interpreter).

Exercising the FMU: parameters keep their start values; every Real input follows a
deterministic signal inside its [min, max] (``start + a sin(0.7 k + phase)`` when unbounded);
other inputs keep their start values. Outputs are read at every communication point after the
inputs are set, i.e. as our master does. The run uses the default experiment's step size and at
most ``n_steps`` steps. Outputs that are irreproducible by design (wall-clock measurements) or
defined per communication step (e.g. a peak over the last step) are excluded from the exact
comparisons they cannot pass, by name or description patterns (:class:`Options`), and listed
in a note. This module imports no other project module, so it works for any FMU.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import subprocess
import sys
import zipfile
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any
from xml.etree import ElementTree

import numpy as np

ERROR, WARNING, NOTE = "error", "warning", "note"
SKIPPED = "skipped"  # a check that could not run (never reported as "ok")

STATIC_CHECKS = ("fmpy-validation", "variables", "units", "model-structure",
                 "default-experiment", "capabilities")
DYNAMIC_CHECKS = ("calling-sequence", "output-dependencies", "reset", "fmu-state",
                  "variable-step", "two-instances", "wrong-state", "invalid-step",
                  "non-finite-inputs", "bad-parameters")
ALL_CHECKS = STATIC_CHECKS + DYNAMIC_CHECKS

_FATAL = "rejected with fmi2Fatal, expected fmi2Error"
_MARK = "@@compliance "  # worker protocol lines on stdout (the FMU may print too)

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


@dataclass(frozen=True)
class Problem:
    """One finding: the check it belongs to, a readable message, its severity."""

    check: str
    message: str
    severity: str = ERROR

    def __str__(self) -> str:
        return f"[{self.severity}] {self.check}: {self.message}"


def passed(problems: list[Problem]) -> bool:
    """True when no problem is an error (warnings and notes do not fail)."""
    return not any(p.severity == ERROR for p in problems)


def _skipped(checks: tuple[str, ...], reason: str, problems: list[Problem]) -> list[Problem]:
    """``problems`` plus a "skipped" entry for each of ``checks`` that has no finding."""
    seen = {p.check for p in problems}
    return [*problems, *(Problem(c, f"not run: {reason}", SKIPPED) for c in checks
                         if c not in seen)]


# -- static checks -------------------------------------------------------------------------------
def _read_xml(path: Path) -> ElementTree.Element:
    with zipfile.ZipFile(path) as z:
        return ElementTree.fromstring(z.read("modelDescription.xml"))


def _num(text: str | None) -> float | None:
    if text is None:
        return None
    if text in ("true", "false"):
        return 1.0 if text == "true" else 0.0
    try:
        return float(text)
    except ValueError:
        return None


def check_model_description(path: str | Path, strict: bool = True) -> list[Problem]:
    """Static checks on the FMU file. ``strict`` makes project conventions errors (every Real
    has a unit, outputs declare dependencies explicitly, default experiment has a step size);
    otherwise they are warnings."""
    from fmpy import read_model_description
    from fmpy.validation import validate_fmu

    path = Path(path)
    convention = ERROR if strict else WARNING
    problems: list[Problem] = []
    try:
        messages = validate_fmu(str(path))
    except Exception as err:  # a broken archive or XML
        return _skipped(STATIC_CHECKS, "the archive could not be read",
                        [Problem("fmpy-validation", f"cannot be validated: {err}")])
    problems += [Problem("fmpy-validation", str(m).strip()) for m in messages]
    try:
        root = _read_xml(path)
        md = read_model_description(str(path), validate=False)
    except Exception as err:
        return _skipped(STATIC_CHECKS, "modelDescription.xml could not be read",
                        [*problems, Problem("variables", f"modelDescription.xml unreadable: "
                                                         f"{err}")])
    if root.get("fmiVersion") != "2.0":
        problems.append(Problem("capabilities", f"fmiVersion {root.get('fmiVersion')!r}, "
                                                "these checks are for FMI 2.0"))
        return _skipped(STATIC_CHECKS, "not an FMI 2.0 FMU", problems)

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
                problems.append(Problem("units", f"{name}: Real variable without a unit",
                                        convention))
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
                                    "attribute (means 'depends on everything')", convention))
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
                                    convention))
        if de.stepSize is None:
            problems.append(Problem("default-experiment", "DefaultExperiment has no stepSize",
                                    convention))
    cs = md.coSimulation
    if cs is None:
        problems.append(Problem("capabilities", "not a co-simulation FMU"))
    else:
        for flag in ("canHandleVariableCommunicationStepSize", "canGetAndSetFMUstate",
                     "canSerializeFMUstate"):
            if not getattr(cs, flag):
                problems.append(Problem("capabilities", f"{flag} is false; the related "
                                                        "checks are skipped", convention))
    return problems


# -- dynamic checks (run inside the worker) -------------------------------------------------------
class _Host:
    """Loads one FMU for the worker: extraction, variables, instances with captured logs."""

    def __init__(self, path: Path, unzipdir: str, n_steps: int,
                 irreproducible: tuple[str, ...] = (), step_dependent: tuple[str, ...] = ()
                 ) -> None:
        from fmpy import read_model_description

        self.path = path
        self.unzipdir = unzipdir
        self.md = read_model_description(str(path), validate=False)
        self.cs = self.md.coSimulation
        variables = self.md.modelVariables
        self.inputs = [v for v in variables if v.causality == "input"]
        self.outputs = [v for v in variables if v.causality == "output"
                        and v.type in ("Real", "Integer", "Boolean", "Enumeration")]
        self.parameters = [v for v in variables if v.causality == "parameter"]
        self.irreproducible = _matching(self.outputs, irreproducible)
        # outputs declared with an explicit empty dependency list (no direct feedthrough);
        # a missing attribute means "depends on everything" and is not checked
        root = _read_xml(path)
        xml_vars = list(root.find("ModelVariables"))
        outputs_node = root.find("ModelStructure/Outputs")
        self.no_dependencies = {
            xml_vars[int(u.get("index")) - 1].get("name")
            for u in (outputs_node if outputs_node is not None else [])
            if u.get("dependencies") is not None and not u.get("dependencies").split()}
        self.step_dependent = _matching(self.outputs, step_dependent)
        de = self.md.defaultExperiment
        self.start = float(de.startTime) if de is not None and de.startTime is not None else 0.0
        stop = float(de.stopTime) if de is not None and de.stopTime is not None else None
        step = float(de.stepSize) if de is not None and de.stepSize is not None else None
        if step is None:
            step = (stop - self.start) / 100 if stop else 0.01
        self.h = step
        span = round((stop - self.start) / step) if stop else n_steps
        self.n = max(4, min(n_steps, span))

    def instance(self, name: str = "compliance") -> _Instance:
        return _Instance(self, name)

    # inputs and outputs -------------------------------------------------------------------------
    def input_values(self, k: int, phase: float = 0.0) -> list[tuple[Any, Any]]:
        values = []
        for v in self.inputs:
            if v.type != "Real":
                continue
            lo, hi, st = _num(v.min), _num(v.max), _num(v.start) or 0.0
            s = math.sin(0.7 * k + phase)
            if lo is not None and hi is not None:
                value = 0.5 * (lo + hi) + 0.4 * (hi - lo) * s
            else:
                value = st + 0.1 * max(1.0, abs(st)) * s
                value = max(value, lo) if lo is not None else value
                value = min(value, hi) if hi is not None else value
            values.append((v, value))
        return values


def _matching(outputs: list, patterns: tuple[str, ...]) -> frozenset[int]:
    """Indices of outputs whose name or ``description:...`` matches a pattern (fnmatch)."""
    from fnmatch import fnmatch

    found = set()
    for i, v in enumerate(outputs):
        for pat in patterns:
            if pat.startswith("description:"):
                if fnmatch((v.description or "").lower(), pat[len("description:"):].lower()):
                    found.add(i)
            elif fnmatch(v.name, pat):
                found.add(i)
    return frozenset(found)


class _Instance:
    """One FMU instance; ``call`` returns the status instead of raising, logs are kept."""

    def __init__(self, host: _Host, name: str) -> None:
        from fmpy.fmi2 import FMU2Slave

        from cosim.run.master import logging_callbacks

        self.host = host
        self.messages: list[tuple[int, str]] = []
        self._callbacks = logging_callbacks(lambda status, text:
                                            self.messages.append((status, text)))
        self.fmu = FMU2Slave(guid=host.md.guid, unzipDirectory=host.unzipdir,
                             modelIdentifier=host.cs.modelIdentifier, instanceName=name)
        self.fmu.instantiate(callbacks=self._callbacks, loggingOn=True)
        self.alive = True

    def call(self, method: str, *args: Any, **kwargs: Any) -> tuple[int, Any]:
        """(status, result) of one FMI call; status 0 is fmi2OK."""
        from fmpy.fmi1 import FMICallException

        try:
            return 0, getattr(self.fmu, method)(*args, **kwargs)
        except FMICallException as err:
            return err.status, None

    def must(self, method: str, *args: Any, **kwargs: Any) -> Any:
        status, result = self.call(method, *args, **kwargs)
        if status > 1:
            raise _CallFailed(method, status, self.messages)
        return result

    def init(self) -> None:
        self.must("setupExperiment", startTime=self.host.start)
        self.must("enterInitializationMode")
        self.must("exitInitializationMode")

    def set_inputs(self, values: list[tuple[Any, Any]]) -> None:
        for v, value in values:
            self.must("setReal", [v.valueReference], [value])

    def read_outputs(self) -> list[float]:
        out = []
        for v in self.host.outputs:
            if v.type == "Real":
                out.append(self.must("getReal", [v.valueReference])[0])
            elif v.type == "Boolean":
                out.append(float(self.must("getBoolean", [v.valueReference])[0]))
            else:
                out.append(float(self.must("getInteger", [v.valueReference])[0]))
        return out

    def free(self) -> None:
        if self.alive:
            self.fmu.freeInstance()
            self.alive = False


class _CallFailed(Exception):
    def __init__(self, method: str, status: int, messages: list[tuple[int, str]]) -> None:
        label = {2: "discard", 3: "error", 4: "fatal"}.get(status, str(status))
        said = " | ".join(m for _, m in messages[-2:]).strip()
        super().__init__(f"{method} returned fmi2{label.capitalize()} in a nominal run"
                         + (f"; FMU says: {said}" if said else ""))


def _run(inst: _Instance, k0: int, k1: int, phase: float = 0.0,
         splits: tuple[float, ...] = (1.0,)) -> np.ndarray:
    """Steps k0..k1-1: set inputs, read outputs, doStep (split in parts of ``splits``).
    Returns outputs at points k0..k1 (the last read after the final step, inputs of k1)."""
    host = inst.host
    rows = []
    for k in range(k0, k1 + 1):
        inst.set_inputs(host.input_values(k, phase))
        rows.append(inst.read_outputs())
        if k == k1:
            break
        t = host.start + k * host.h
        for part in splits:
            inst.must("doStep", currentCommunicationPoint=t, communicationStepSize=part * host.h)
            t += part * host.h
    return np.array(rows, dtype=float).reshape(len(rows), len(host.outputs))


def _nominal(host: _Host, phase: float = 0.0, name: str = "nominal") -> np.ndarray:
    inst = host.instance(name)
    inst.init()
    rows = _run(inst, 0, host.n, phase)
    inst.must("terminate")
    inst.free()
    return rows


def _differs(a: np.ndarray, b: np.ndarray, tol: float = 0.0,
             ignore: frozenset[int] = frozenset()) -> str | None:
    """None when equal (NaN == NaN) within ``tol`` (relative to 1 + |b|), else a description.
    Output columns in ``ignore`` are not compared."""
    if a.shape != b.shape:
        return f"shapes differ {a.shape} vs {b.shape}"
    bad = ~(np.isclose(a, b, rtol=tol, atol=tol, equal_nan=True) if tol else
            ((a == b) | (np.isnan(a) & np.isnan(b))))
    bad[:, sorted(ignore)] = False
    if not bad.any():
        return None
    k, j = np.argwhere(bad)[0]
    return (f"step {k}, output #{j}: {float(a[k, j])!r} vs {float(b[k, j])!r} "
            f"({int(bad.sum())} values differ)")


def _out_name(host: _Host, message: str) -> str:
    import re

    m = re.search(r"output #(\d+)", message)
    if m:
        return message.replace(m.group(0), host.outputs[int(m.group(1))].name)
    return message


def _rejection(inst: _Instance, statuses: list[int], what: str, check: str) -> list[Problem]:
    """A call sequence that should have been rejected: judge its statuses and the log."""
    worst = max(statuses) if statuses else 0
    logged = [m for s, m in inst.messages if m.strip()]
    if worst <= 1:
        return [Problem(check, f"{what}: accepted (fmi2OK); expected fmi2Error")]
    problems = []
    if not logged:
        problems.append(Problem(check, f"{what}: rejected without a log message"))
    if worst == 2:
        problems.append(Problem(check, f"{what}: rejected with fmi2Discard, expected fmi2Error",
                                WARNING))
    if worst == 4:
        problems.append(Problem(check, f"{what}: {_FATAL}"))
    return problems


def _check_calling_sequence(host: _Host, ctx: dict) -> list[Problem]:
    inst = host.instance("sequence")
    inst.init()
    rows = _run(inst, 0, host.n)
    inst.must("terminate")
    errors = [m for s, m in inst.messages if s >= 3]
    inst.free()
    ctx["reference"] = rows
    problems = []
    if errors:
        problems.append(Problem("calling-sequence", f"error messages in a nominal run: "
                                                    f"{errors[0]}"))
    if not np.isfinite(rows).all():
        k, j = np.argwhere(~np.isfinite(rows))[0]
        problems.append(Problem("calling-sequence", f"output {host.outputs[j].name} is "
                                                    f"{rows[k, j]} at step {k}"))
    return problems


def _probe_inputs(host: _Host, sign: float, scale: float) -> list[tuple[Any, Any]]:
    """Real inputs pushed to one side: near min/max when bounded, else start +- scale."""
    values = []
    for v in host.inputs:
        if v.type != "Real":
            continue
        lo, hi, st = _num(v.min), _num(v.max), _num(v.start) or 0.0
        if lo is not None and hi is not None:
            value = 0.5 * (lo + hi) + sign * 0.45 * (hi - lo)
        else:
            value = st + sign * scale * max(1.0, abs(st))
            value = max(value, lo) if lo is not None else value
            value = min(value, hi) if hi is not None else value
        values.append((v, value))
    return values


def _check_output_dependencies(host: _Host, ctx: dict) -> list[Problem]:
    """Outputs declared without dependencies must not react to the inputs of the same
    instant. Two instances follow the same run to step k and step on to k+1 without reading;
    there they get opposite inputs (small, large, huge: a saturated output hides small ones)
    before the first read (a sampled controller computes its event on that read), and the
    declared-independent outputs must agree."""
    independent = [i for i, v in enumerate(host.outputs) if v.name in host.no_dependencies]
    if not independent or not [v for v in host.inputs if v.type == "Real"]:
        return []
    k = host.n // 2
    moved: set[int] = set()
    for scale in (0.1, 10.0, 1000.0):
        readings = []
        for sign in (1.0, -1.0):
            inst = host.instance("dependencies")
            inst.init()
            _run(inst, 0, k)
            inst.must("doStep", currentCommunicationPoint=host.start + k * host.h,
                      communicationStepSize=host.h)
            inst.set_inputs(_probe_inputs(host, sign, scale))
            readings.append(np.array(inst.read_outputs()))
            inst.free()
        a, b = readings
        moved |= {i for i in independent if not (a[i] == b[i] or np.isnan(a[i]) and np.isnan(b[i]))}
        if moved:
            break
    return [Problem("output-dependencies", f"output {host.outputs[i].name} changed when the "
                    "inputs changed at the same instant, but ModelStructure declares no "
                    "dependency on inputs") for i in sorted(moved)]


def _check_reset(host: _Host, ctx: dict) -> list[Problem]:
    inst = host.instance("reset")
    inst.init()
    first = _run(inst, 0, host.n)
    status, _ = inst.call("reset")
    if status > 1:
        inst.free()
        return [Problem("reset", f"fmi2Reset returned status {status}")]
    inst.init()
    second = _run(inst, 0, host.n)
    inst.free()
    diff = _differs(second, first, ignore=host.irreproducible)
    return [Problem("reset", "the run after fmi2Reset differs from the first run: "
                    + _out_name(host, diff))] if diff else []


def _check_fmu_state(host: _Host, ctx: dict) -> list[Problem]:
    if not host.cs.canGetAndSetFMUstate:
        return [Problem("fmu-state", "canGetAndSetFMUstate is false: skipped", NOTE)]
    problems = []
    k = host.n // 2
    inst = host.instance("state")
    inst.init()
    _run(inst, 0, k)
    state = inst.must("getFMUstate")
    rest = _run(inst, k, host.n)
    inst.must("setFMUstate", state)
    again = _run(inst, k, host.n)
    diff = _differs(again, rest, ignore=host.irreproducible)
    if diff:
        problems.append(Problem("fmu-state", "after fmi2SetFMUstate the rest of the run "
                                             "differs: " + _out_name(host, diff)))
    if host.cs.canSerializeFMUstate:
        data = inst.must("serializeFMUstate", state)
        fresh = host.instance("state-copy")
        restored = fresh.must("deSerializeFMUstate", data)
        fresh.must("setFMUstate", restored)
        copy_rest = _run(fresh, k, host.n)
        diff = _differs(copy_rest, rest, ignore=host.irreproducible)
        if diff:
            problems.append(Problem("fmu-state", "a fresh instance given the serialized state "
                                    "continues differently: " + _out_name(host, diff)))
        fresh.free()
    else:
        problems.append(Problem("fmu-state", "canSerializeFMUstate is false: skipped", NOTE))
    inst.must("freeFMUstate", state)
    inst.free()
    return problems


def _check_variable_step(host: _Host, ctx: dict) -> list[Problem]:
    if not host.cs.canHandleVariableCommunicationStepSize:
        return [Problem("variable-step", "canHandleVariableCommunicationStepSize is false: "
                                         "skipped", NOTE)]
    reference = ctx.get("reference")
    if reference is None:
        reference = _nominal(host)
    problems = []
    for splits in ((0.5, 0.5), (0.25, 0.75)):
        inst = host.instance("variable-step")
        inst.init()
        rows = _run(inst, 0, host.n, splits=splits)
        inst.free()
        diff = _differs(rows, reference, ctx["step_tolerance"],
                        ignore=host.irreproducible | host.step_dependent)
        if diff:
            problems.append(Problem("variable-step", f"steps split {splits} x h give other "
                                    f"results than steps of h = {host.h} s (tolerance "
                                    f"{ctx['step_tolerance']}): " + _out_name(host, diff)))
    return problems


def _check_two_instances(host: _Host, ctx: dict) -> list[Problem]:
    reference = ctx.get("reference")
    if reference is None:
        reference = _nominal(host)
    other = _nominal(host, phase=2.3, name="other")
    a, b = host.instance("a"), host.instance("b")
    a.init()
    b.init()
    rows_a, rows_b = [], []
    for k in range(host.n):  # interleave every call
        rows_a.append(_run(a, k, k + 1)[0])
        rows_b.append(_run(b, k, k + 1, phase=2.3)[0])
    a.free()
    b.free()
    n = host.n
    problems = []
    for label, rows, ref in (("first", rows_a, reference[:n]), ("second", rows_b, other[:n])):
        diff = _differs(np.array(rows).reshape(ref.shape), ref, ignore=host.irreproducible)
        if diff:
            problems.append(Problem("two-instances", f"the {label} of two interleaved instances "
                                    "differs from a run alone: " + _out_name(host, diff)))
    return problems


def _check_wrong_state(host: _Host, ctx: dict) -> list[Problem]:
    problems = []
    h, t0 = host.h, host.start

    def case(what: str, prepare: list[tuple[str, tuple, dict]],
             wrong: tuple[str, tuple, dict]) -> None:
        inst = host.instance("wrong-state")
        for method, args, kwargs in prepare:
            inst.must(method, *args, **kwargs)
        inst.messages.clear()
        status, _ = inst.call(wrong[0], *wrong[1], **wrong[2])
        problems.extend(_rejection(inst, [status], what, "wrong-state"))
        if status < 4:
            inst.free()

    setup = ("setupExperiment", (), {"startTime": t0})
    enter = ("enterInitializationMode", (), {})
    leave = ("exitInitializationMode", (), {})
    step = ("doStep", (), {"currentCommunicationPoint": t0, "communicationStepSize": h})
    case("fmi2DoStep before initialisation", [setup], step)
    case("fmi2ExitInitializationMode without fmi2EnterInitializationMode", [setup], leave)
    case("fmi2DoStep after fmi2Terminate", [setup, enter, leave, step,
                                            ("terminate", (), {})],
         ("doStep", (), {"currentCommunicationPoint": t0 + h, "communicationStepSize": h}))
    fixed = [v for v in host.parameters if v.variability == "fixed" and v.type == "Real"]
    if fixed:
        v = fixed[0]
        value = (_num(v.start) or 0.0)
        case(f"fmi2SetReal of fixed parameter {v.name} after initialisation",
             [setup, enter, leave], ("setReal", ([v.valueReference], [value]), {}))
    return problems


def _check_invalid_step(host: _Host, ctx: dict) -> list[Problem]:
    problems = []
    for what, size in (("negative", -host.h), ("zero", 0.0), ("NaN", math.nan)):
        inst = host.instance("invalid-step")
        inst.init()
        inst.messages.clear()
        status, _ = inst.call("doStep", currentCommunicationPoint=host.start,
                              communicationStepSize=size)
        problems += _rejection(inst, [status], f"fmi2DoStep with a {what} step size",
                               "invalid-step")
        if status < 4:
            inst.free()
    return problems


def _check_non_finite_inputs(host: _Host, ctx: dict) -> list[Problem]:
    problems = []
    for v in [v for v in host.inputs if v.type == "Real"]:
        for value in (math.nan, math.inf, -math.inf):
            inst = host.instance("non-finite")
            inst.init()
            inst.messages.clear()
            statuses = [inst.call("setReal", [v.valueReference], [value])[0]]
            if statuses[0] <= 1:  # accepted for now: the next step or read must refuse it
                statuses.append(inst.call("doStep", currentCommunicationPoint=host.start,
                                          communicationStepSize=host.h)[0])
                if statuses[-1] <= 1:
                    outs = np.array(inst.read_outputs())
                    if not np.isfinite(outs).all():
                        problems.append(Problem("non-finite-inputs", f"input {v.name} = "
                                                f"{value}: accepted and propagated to outputs"))
                        inst.free()
                        continue
            problems += _rejection(inst, statuses, f"input {v.name} = {value}",
                                   "non-finite-inputs")
            if max(statuses) < 4:
                inst.free()
    return problems


def _check_bad_parameters(host: _Host, ctx: dict) -> list[Problem]:
    problems = []
    for v in host.parameters:
        if v.type not in ("Real", "Integer"):
            continue
        lo, hi = _num(v.min), _num(v.max)
        cases = []
        if lo is not None:
            cases.append(("below min", lo - max(1.0, abs(lo))))
        if hi is not None:
            cases.append(("above max", hi + max(1.0, abs(hi))))
        if v.type == "Real":
            cases.append(("NaN", math.nan))
        for label, value in cases:
            inst = host.instance("bad-parameter")
            inst.must("setupExperiment", startTime=host.start)
            inst.messages.clear()
            if v.type == "Real":
                statuses = [inst.call("setReal", [v.valueReference], [value])[0]]
            else:
                statuses = [inst.call("setInteger", [v.valueReference], [int(value)])[0]]
            if statuses[-1] <= 1:
                statuses.append(inst.call("enterInitializationMode")[0])
            if statuses[-1] <= 1:
                statuses.append(inst.call("exitInitializationMode")[0])
            problems += _rejection(inst, statuses, f"parameter {v.name} = {value} ({label})",
                                   "bad-parameters")
            if max(statuses) < 4:
                inst.free()
    return problems


_DYNAMIC = {
    "calling-sequence": _check_calling_sequence,
    "output-dependencies": _check_output_dependencies,
    "reset": _check_reset,
    "fmu-state": _check_fmu_state,
    "variable-step": _check_variable_step,
    "two-instances": _check_two_instances,
    "wrong-state": _check_wrong_state,
    "invalid-step": _check_invalid_step,
    "non-finite-inputs": _check_non_finite_inputs,
    "bad-parameters": _check_bad_parameters,
}


def _collapse_fatal(problems: list[Problem]) -> list[Problem]:
    """One error per check for the rejections that returned fmi2Fatal instead of fmi2Error."""
    fatal = [p for p in problems if p.severity == ERROR and p.message.endswith(_FATAL)]
    if not fatal:
        return problems
    first = fatal[0].message[: -len(_FATAL)].rstrip(": ")
    said = (f"{first}: {_FATAL}" if len(fatal) == 1 else
            f"{len(fatal)} rejections returned fmi2Fatal, expected fmi2Error (e.g. {first})")
    error = Problem(fatal[0].check, f"{said}. fmi2Fatal declares every instance of the FMU "
                    "unusable, so a master cannot recover; plain pythonfmu 0.7 binaries return "
                    "it for any Python exception (FMUs from `cosim build` return fmi2Error "
                    "through their shim)")
    return [p for p in problems if p not in fatal] + [error]


def _emit(kind: str, payload: Any) -> None:
    print(_MARK + json.dumps([kind, payload]), flush=True)


def _worker(args: dict) -> None:
    """Run dynamic checks, reporting progress on stdout (see ``_run_worker``)."""
    from fmpy import extract

    paths = [Path(p) for p in args["paths"]]
    unzipdirs = [extract(str(p)) for p in paths]
    try:
        hosts = [_Host(p, d, args["n_steps"], tuple(args["irreproducible"]),
                       tuple(args["step_dependent"])) for p, d in zip(paths, unzipdirs)]
        if args["mode"] == "together":
            _emit("begin", "together")
            for p in _together(hosts):
                _emit("problem", asdict(p))
            _emit("end", "together")
            return
        host = hosts[0]
        ctx: dict[str, Any] = {"step_tolerance": args["step_tolerance"]}
        if "calling-sequence" not in args["skip"]:
            for label, cols in (("not compared (irreproducible by design)", host.irreproducible),
                                ("not compared across step sizes (defined per communication "
                                 "step)", host.step_dependent - host.irreproducible)):
                if cols:
                    names = ", ".join(host.outputs[i].name for i in sorted(cols))
                    _emit("problem", asdict(Problem("calling-sequence", f"outputs {label}: "
                                                    f"{names}", NOTE)))
        for name in DYNAMIC_CHECKS:
            if name in args["skip"]:
                continue
            _emit("begin", name)
            try:
                problems = _DYNAMIC[name](host, ctx)
            except _CallFailed as err:
                problems = [Problem(name, str(err))]
            except Exception as err:  # a bug in the FMU surfacing as a host exception
                problems = [Problem(name, f"{type(err).__name__}: {err}")]
            for p in _collapse_fatal(problems):
                _emit("problem", asdict(p))
            _emit("end", name)
    finally:
        for d in unzipdirs:
            shutil.rmtree(d, ignore_errors=True)


def _together(hosts: list[_Host]) -> list[Problem]:
    """All FMUs alone, then all interleaved in this process: results must not change."""
    alone = [_nominal(h) for h in hosts]
    insts = [h.instance(f"together{i}") for i, h in enumerate(hosts)]
    for inst in insts:
        inst.init()
    rows: list[list[np.ndarray]] = [[] for _ in hosts]
    for k in range(max(h.n for h in hosts)):
        for i, (h, inst) in enumerate(zip(hosts, insts)):
            if k < h.n:
                rows[i].append(_run(inst, k, k + 1)[0])
    problems = []
    for h, inst, r, ref in zip(hosts, insts, rows, alone):
        inst.free()
        diff = _differs(np.array(r).reshape(ref[:h.n].shape), ref[:h.n],
                        ignore=h.irreproducible)
        if diff:
            problems.append(Problem("together", f"{h.path.name} run interleaved with the "
                                    "other FMUs differs from a run alone: "
                                    + _out_name(h, diff)))
    return problems


def _run_worker(args: dict, checks: tuple[str, ...], timeout: float) -> list[Problem]:
    """Run the worker until every check has finished, crashed or hung (then restart it)."""
    problems: list[Problem] = []
    done: set[str] = set()
    while True:
        args = {**args, "skip": sorted(done)}
        cmd = [sys.executable, "-m", "cosim.interop.compliance", json.dumps(args)]
        env = dict(os.environ)
        root = str(Path(__file__).resolve().parents[2])
        env["PYTHONPATH"] = root + os.pathsep + env.get("PYTHONPATH", "")
        current: str | None = None
        try:
            proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, env=env)
            out, err, code, hung = proc.stdout, proc.stderr, proc.returncode, False
        except subprocess.TimeoutExpired as exc:
            out = exc.stdout.decode() if isinstance(exc.stdout, bytes) else (exc.stdout or "")
            err, code, hung = "", None, True
        for line in out.splitlines():
            if not line.startswith(_MARK):
                continue
            kind, payload = json.loads(line[len(_MARK):])
            if kind == "begin":
                current = payload
            elif kind == "end":
                done.add(payload)
                current = None
            elif kind == "problem":
                problems.append(Problem(**payload))
        if current is None and not hung and code == 0:
            return problems
        if current is None:  # died outside a check (loading): report once and stop
            tail = err.strip().splitlines()[-1] if err.strip() else f"exit status {code}"
            problems.append(Problem("calling-sequence", f"the host process failed while "
                                    f"loading the FMU: {tail}"))
            return _skipped(tuple(c for c in checks if c not in done),
                            "the FMU could not be loaded", problems)
        if hung:
            problems.append(Problem(current, f"hang: no progress for {timeout:.0f} s (the "
                                             "host was killed)"))
        else:
            signal = f"signal {-code}" if code < 0 else f"exit status {code}"
            problems.append(Problem(current, f"the host process crashed ({signal}) during "
                                             "this check"))
        done.add(current)
        if all(c in done for c in checks):
            return problems


# -- public API ---------------------------------------------------------------------------------
@dataclass
class Options:
    """Knobs of :func:`check_fmu`."""

    strict: bool = True  # project conventions are errors, not warnings
    step_tolerance: float = 1e-9  # variable-step results vs fixed-step results (relative)
    n_steps: int = 40  # communication steps per run
    timeout: float = 120.0  # s, per worker process (a hang is reported after this)
    # outputs (fnmatch on name, or "description:<pattern>") excluded from the exact
    # reproducibility comparisons (reset, state, instances): wall-clock measurements
    irreproducible: tuple[str, ...] = ("*wall_time*", "*solve_time*", "*cpu_time*",
                                       "description:*wall-clock*")
    # outputs excluded only from the variable-step comparison: defined per communication step
    step_dependent: tuple[str, ...] = ("description:*communication step*",)
    dynamic: bool = True


def _worker_options(opts: Options) -> dict[str, Any]:
    return {"n_steps": opts.n_steps, "step_tolerance": opts.step_tolerance,
            "irreproducible": list(opts.irreproducible),
            "step_dependent": list(opts.step_dependent)}


def check_fmu(path: str | Path, options: Options | None = None) -> list[Problem]:
    """All compliance checks of one FMU file; an empty list (or only warnings/notes) passes."""
    opts = options or Options()
    path = Path(path)
    if not path.is_file():
        return [Problem("fmpy-validation", f"{path}: no such file")]
    problems = check_model_description(path, strict=opts.strict)
    if not opts.dynamic:
        return problems
    loadable = not any(p.check in ("variables", "capabilities") and "unreadable" in p.message
                       or p.message == "not a co-simulation FMU"
                       or p.severity == SKIPPED for p in problems)
    if not loadable:
        return _skipped(DYNAMIC_CHECKS, "the FMU could not be read or is not for "
                        "co-simulation", problems)
    args = {"mode": "single", "paths": [str(path.resolve())], **_worker_options(opts)}
    return problems + _run_worker(args, DYNAMIC_CHECKS, opts.timeout)


def check_together(paths: list[str | Path], options: Options | None = None) -> list[Problem]:
    """Load all ``paths`` in one process and check each runs as it does alone."""
    opts = options or Options()
    args = {"mode": "together", "paths": [str(Path(p).resolve()) for p in paths],
            **_worker_options(opts)}
    return _run_worker(args, ("together",), opts.timeout)


def format_report(path: str | Path, problems: list[Problem],
                  checks: tuple[str, ...] = ALL_CHECKS) -> str:
    """A readable report: one line per check (ok / FAIL / warn), then the findings."""
    lines = [f"FMU {path}"]
    by_check: dict[str, list[Problem]] = {}
    for p in problems:
        by_check.setdefault(p.check, []).append(p)
    for check in [*checks, *[c for c in by_check if c not in checks]]:
        found = by_check.get(check, [])
        severities = {p.severity for p in found}
        label = ("FAIL" if ERROR in severities else "warn" if WARNING in severities
                 else "skip" if SKIPPED in severities else "ok")
        if label == "skip":
            reason = next(p.message for p in found if p.severity == SKIPPED)
            lines.append(f"  {label:<4}  {check}  ({reason.removeprefix('not run: ')})")
            continue
        lines.append(f"  {label:<4}  {check}")
        for p in found:
            if p.severity != SKIPPED:
                lines.append(f"          {p.severity}: {p.message}")
    n_err = sum(p.severity == ERROR for p in problems)
    n_warn = sum(p.severity == WARNING for p in problems)
    n_skip = len({p.check for p in problems if p.severity == SKIPPED})
    verdict = "PASSED" if n_err == 0 else "FAILED"
    lines.append(f"  {verdict}: {n_err} error(s), {n_warn} warning(s)"
                 + (f", {n_skip} check(s) skipped" if n_skip else ""))
    return "\n".join(lines)


def _main(argv: list[str]) -> int:
    if len(argv) == 1 and argv[0].startswith("{"):
        _worker(json.loads(argv[0]))
        return 0
    failed = False
    for p in argv:
        problems = check_fmu(p)
        print(format_report(p, problems))
        failed |= not passed(problems)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(_main(sys.argv[1:]))
