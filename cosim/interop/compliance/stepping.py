"""Dynamic checks of communication steps: variable step sizes, invalid step sizes."""

from __future__ import annotations

import math

from cosim.interop.compliance.common import NOTE, Problem
from cosim.interop.compliance.host import _differs, _Host, _nominal, _out_name, _rejection, _run


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


