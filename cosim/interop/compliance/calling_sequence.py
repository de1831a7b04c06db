"""Dynamic checks of the nominal calling sequence: instantiate -> setup -> initialisation ->
doStep* -> terminate -> freeInstance, declared-independent outputs, fmi2Reset, two instances."""

from __future__ import annotations

import numpy as np

from cosim.interop.compliance.common import Problem
from cosim.interop.compliance.host import _differs, _Host, _nominal, _out_name, _probe_inputs, _run


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


