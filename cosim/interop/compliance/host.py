"""The worker's view of one loaded FMU: variables, instances with captured logs, the
deterministic input signal, nominal runs and the comparison helpers the dynamic checks share."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from cosim.interop.compliance.common import (
    _FATAL,
    RECOMMENDED,
    WARNING,
    Problem,
    _num,
    _read_xml,
)
from cosim.interop.compliance.watchdog import CallBoard
from cosim.run.master import logging_callbacks


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


def describe_call(method: str, args: tuple = (), kwargs: dict | None = None,
                  standard: str = "fmi2") -> str:
    """``fmi2DoStep(currentCommunicationPoint=0.0, communicationStepSize=nan)`` (``standard``
    "fmi3": the FMI 3 name)."""
    parts = [repr(a) for a in args] + [f"{k}={v!r}" for k, v in (kwargs or {}).items()]
    name = (method if method.startswith(("fmi2", "fmi3", "dlopen"))
            else standard + method[0].upper() + method[1:])
    return f"{name}({', '.join(parts)})"


class _Watchdog:
    """Announces each FMI call of the worker on a :class:`~cosim.interop.compliance.watchdog.
    CallBoard`, where the supervisor decides whether it hangs (:func:`~cosim.interop.
    compliance.watchdog.supervise`). Without :meth:`start` (the FMU run outside the worker) it
    only keeps the current call."""

    def __init__(self) -> None:
        self.current: str | None = None
        self.board = None

    def start(self, board_path: str) -> None:
        self.board = CallBoard(board_path)

    def call(self, description: str, function: Any, *args: Any, **kwargs: Any) -> Any:
        self.current = description
        if self.board is not None:
            self.board.begin(description)
        try:
            return function(*args, **kwargs)
        finally:
            self.current = None
            if self.board is not None:
                self.board.end()


WATCHDOG = _Watchdog()


class _Instance:
    """One FMU instance; ``call`` returns the status instead of raising, logs are kept. Every
    FMI call goes through :data:`WATCHDOG`."""

    def __init__(self, host: _Host, name: str) -> None:
        from fmpy.fmi2 import FMU2Slave

        self.host = host
        self.messages: list[tuple[int, str]] = []
        self._callbacks = logging_callbacks(lambda status, text:
                                            self.messages.append((status, text)))
        self.fmu = WATCHDOG.call(f"dlopen({host.cs.modelIdentifier})",
                                 FMU2Slave, guid=host.md.guid, unzipDirectory=host.unzipdir,
                                 modelIdentifier=host.cs.modelIdentifier, instanceName=name)
        WATCHDOG.call(describe_call("instantiate", (), {"instanceName": name}),
                      self.fmu.instantiate, callbacks=self._callbacks, loggingOn=True)
        self.alive = True

    def call(self, method: str, *args: Any, **kwargs: Any) -> tuple[int, Any]:
        """(status, result) of one FMI call; status 0 is fmi2OK."""
        from fmpy.fmi1 import FMICallException

        try:
            return 0, WATCHDOG.call(describe_call(method, args, kwargs),
                                    getattr(self.fmu, method), *args, **kwargs)
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
            WATCHDOG.call(describe_call("freeInstance"), self.fmu.freeInstance)
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
        problems.append(Problem(check, f"{what}: rejected without a log message",
                                requirement=RECOMMENDED, clause="2.1.5 (logger callback: "
                                "an FMU should say why it rejects a call)"))
    if worst == 2:
        problems.append(Problem(check, f"{what}: rejected with fmi2Discard, expected fmi2Error",
                                WARNING))
    if worst == 4:
        problems.append(Problem(check, f"{what}: {_FATAL}", requirement=RECOMMENDED,
                                clause="2.1.3 (fmi2Fatal: all instances unusable)"))
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


