"""Dynamic checks of error handling: calls in the wrong state, non-finite inputs, bad
parameters; fmi2Fatal rejections collapsed into one error per check."""

from __future__ import annotations

import math

import numpy as np

from cosim.interop.compliance.common import _FATAL, ERROR, Problem, _num
from cosim.interop.compliance.host import _Host, _rejection


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
                    "through their shim)", requirement=fatal[0].requirement,
                    clause=fatal[0].clause)
    return [p for p in problems if p not in fatal] + [error]


