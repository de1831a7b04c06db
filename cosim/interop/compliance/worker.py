"""The worker subprocess running the dynamic checks (``python -m
cosim.interop.compliance.worker ARGS_JSON``) and its supervisor ``_run_worker``, which restarts
it after a crash or a hang and reports the check it was in."""

from __future__ import annotations

import json
import os
import shutil
import sys
import tempfile
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np

from cosim.interop.compliance.calling_sequence import (
    _check_calling_sequence,
    _check_output_dependencies,
    _check_reset,
    _check_two_instances,
)
from cosim.interop.compliance.clocks import DYNAMIC as CLOCKS
from cosim.interop.compliance.common import (
    _MARK,
    DYNAMIC_CHECKS,
    FMI3_CS_CHECKS,
    FMI3_DYNAMIC_CHECKS,
    NOTE,
    Problem,
    skipped,
)
from cosim.interop.compliance.errors import (
    _check_bad_parameters,
    _check_non_finite_inputs,
    _check_wrong_state,
    _collapse_fatal,
)
from cosim.interop.compliance.fmi3 import DYNAMIC, _Failed3, _Host3
from cosim.interop.compliance.host import (
    WATCHDOG,
    _CallFailed,
    _differs,
    _Host,
    _nominal,
    _out_name,
    _run,
)
from cosim.interop.compliance.state import _check_fmu_state
from cosim.interop.compliance.stepping import _check_invalid_step, _check_variable_step
from cosim.interop.compliance.watchdog import (
    INSTANTIATE_CALLS,
    Budget,
    CallBoard,
    Limits,
    call_name,
    supervise,
)
from cosim.run.archive import ArchiveLimits, extract

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


def _emit(kind: str, payload: Any) -> None:
    print(_MARK + json.dumps([kind, payload]), flush=True)


def _worker(args: dict) -> None:
    """Run dynamic checks, reporting progress on stdout (see ``_run_worker``)."""
    if args.get("board"):
        WATCHDOG.start(args["board"])
    paths = [Path(p) for p in args["paths"]]
    limits = ArchiveLimits(**args["limits"]) if "limits" in args else ArchiveLimits()
    unzipdirs: list[str] = []
    try:
        for p in paths:
            unzipdirs.append(extract(p, limits))
        if args["mode"] == "fmi3":
            _fmi3_worker(args, paths[0], unzipdirs[0])
            return
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


def _fmi3_worker(args: dict, path: Path, unzipdir: str) -> None:
    """The FMI 3.0 dynamic checks (:mod:`cosim.interop.compliance.fmi3`), same protocol."""
    host = _Host3(path, unzipdir, args["n_steps"], tuple(args["irreproducible"]))
    checks = {**DYNAMIC, **CLOCKS}
    ctx: dict[str, Any] = {}
    for name in FMI3_DYNAMIC_CHECKS:
        if name in args["skip"]:
            continue
        _emit("begin", name)
        try:
            if host.cs is None and name in FMI3_CS_CHECKS:
                problems = [Problem(name, "not applicable: no CoSimulation interface", NOTE)]
            else:
                problems = checks[name](host, ctx)
        except _Failed3 as err:
            problems = [Problem(name, str(err))]
        except Exception as err:  # a bug in the FMU surfacing as a host exception
            problems = [Problem(name, f"{type(err).__name__}: {err}")]
        for p in problems:
            _emit("problem", asdict(p))
        _emit("end", name)


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


def _run_worker(args: dict, checks: tuple[str, ...], limits: Limits) -> list[Problem]:
    """Run the worker until every check has finished, crashed or hung (then restart it for
    the remaining checks). :func:`~cosim.interop.compliance.watchdog.supervise` decides hangs
    on the FMU's own progress; ``limits.budget`` bounds all the worker's runs for this FMU. A
    crash or hang in loading or instantiating the FMU, or a second one in the same FMI
    function, ends the checks: the remaining ones are reported as skipped."""
    problems: list[Problem] = []
    done: set[str] = set()
    failed_in: dict[str, str] = {}  # FMI function -> the check that crashed or hung in it
    budget = Budget(limits.budget)
    env = dict(os.environ)
    root = str(Path(__file__).resolve().parents[3])
    env["PYTHONPATH"] = root + os.pathsep + env.get("PYTHONPATH", "")
    with tempfile.TemporaryDirectory(prefix="cosim-compliance-") as tmp:
        board = CallBoard(Path(tmp) / "board", create=True)
        try:
            while True:
                run_args = {**args, "skip": sorted(done), "board": str(board.path)}
                cmd = [sys.executable, "-m", "cosim.interop.compliance.worker",
                       json.dumps(run_args)]
                with tempfile.TemporaryFile("w+") as out, tempfile.TemporaryFile("w+") as err:
                    outcome = supervise(cmd, env, board, limits, budget, out, err)
                    out.seek(0)
                    err.seek(0)
                    stdout, stderr = out.read(), err.read()
                current: str | None = None
                for line in stdout.splitlines():
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
                if current is None and not outcome.hang and outcome.returncode == 0:
                    return problems
                if current is None and not outcome.hang:
                    # died outside a check (loading): report once and stop
                    tail = (stderr.strip().splitlines()[-1] if stderr.strip()
                            else outcome.describe())
                    # reported under the first check (the calling sequence of its standard)
                    problems.append(Problem(checks[0], "the host process failed "
                                            f"while loading the FMU: {tail}"))
                    return skipped(tuple(c for c in checks if c not in done),
                                   "the FMU could not be loaded", problems)
                check = current or next(c for c in checks if c not in done)
                problems.append(Problem(check, outcome.describe()
                                        + ("" if outcome.hang else " during this check")))
                done.add(check)
                function = call_name(outcome.call)
                rest = tuple(c for c in checks if c not in done)
                what = "hangs" if outcome.hang else "crashes"
                if outcome.hang == "budget":
                    return skipped(rest, f"the checks of this FMU ran out of their budget "
                                   f"(--timeout, in {check})", problems)
                if function and (function.startswith(INSTANTIATE_CALLS)
                                 or function in failed_in):
                    where = ", ".join(sorted({failed_in.get(function, check), check}))
                    return skipped(rest, f"the FMU {what} in {function} (see {where})",
                                   problems)
                if function:
                    failed_in[function] = check
                if not rest:
                    return problems
        finally:
            board.close()


if __name__ == "__main__":
    _worker(json.loads(sys.argv[1]))
