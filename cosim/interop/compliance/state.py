"""Dynamic check of FMU state: get/set and serialize/deserialize mid-run reproduce the rest."""

from __future__ import annotations

from cosim.interop.compliance.common import NOTE, Problem
from cosim.interop.compliance.host import _differs, _Host, _out_name, _run


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


