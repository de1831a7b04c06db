"""FMI 2.0 co-simulation compliance checks for any FMU (ours or a third party's).

``check_fmu(path)`` returns a list of :class:`Problem`; ``format_report`` renders it. The
checks:

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
  Python exception, ours go through a shim that returns fmi2Error, see ``cosim/build/python.py``).

The dynamic checks run in a worker subprocess (``python -m cosim.interop.compliance.worker``), so an
FMU that crashes or hangs the host is reported as a problem of the check it was in, naming the
FMI call, and the worker is restarted for the remaining checks (not after a crash or hang in
loading or instantiating the FMU, or a second one in the same FMI function: every further check
would meet it). Hangs are decided on the FMU's own progress, never on a bare wall-clock figure
(:mod:`cosim.interop.compliance.watchdog`). ``check_together(paths)`` loads several FMUs in
one process and checks that they do not disturb each other (pythonfmu FMUs share one interpreter).

Exercising the FMU: parameters keep their start values; every Real input follows a
deterministic signal inside its [min, max] (``start + a sin(0.7 k + phase)`` when unbounded);
other inputs keep their start values. Outputs are read at every communication point after the
inputs are set, i.e. as our master does. The run uses the default experiment's step size and at
most ``n_steps`` steps. Outputs that are irreproducible by design (wall-clock measurements) or
defined per communication step (e.g. a peak over the last step) are excluded from the exact
comparisons they cannot pass, by name or description patterns (:class:`Options`), and listed
in a note. The package imports no plant or controller, so it works for any FMU.

Modules: ``common`` (Problem, severities), ``model_description`` (static checks),
``host`` (loading and running an FMU), ``calling_sequence``, ``state``, ``stepping``,
``errors`` (the dynamic check families), ``fmi3`` (the FMI 3.0 checks), ``clocks`` (FMI 3.0
Clocks and Scheduled Execution), ``worker`` (the subprocess and its supervisor).
"""

from __future__ import annotations

import zipfile
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from cosim.interop.compliance.clocks import clock_checks
from cosim.interop.compliance.common import (
    ALL_CHECKS,
    CLAUSES,
    CONVENTION,
    DYNAMIC_CHECKS,
    ERROR,
    FMI3_CHECKS,
    FMI3_DYNAMIC_CHECKS,
    FMI3_STATIC_CHECKS,
    NOTE,
    RECOMMENDED,
    REQUIRED,
    SKIPPED,
    STATIC_CHECKS,
    WARNING,
    Problem,
    _read_xml,
    classify,
    passed,
    skipped,
    standard_of,
)
from cosim.interop.compliance.fmi3 import static_checks
from cosim.interop.compliance.host import _Host
from cosim.interop.compliance.model_description import check_model_description
from cosim.interop.compliance.watchdog import SETUP_CALL_ALLOWANCE, Limits
from cosim.interop.compliance.worker import _run_worker
from cosim.run.archive import ArchiveLimits, ArchiveRefused, inspect

__all__ = ["ALL_CHECKS", "CLAUSES", "CONVENTION", "DYNAMIC_CHECKS", "ERROR", "FMI3_CHECKS",
           "FMI3_DYNAMIC_CHECKS", "FMI3_STATIC_CHECKS", "NOTE", "checks_for",
           "RECOMMENDED", "REQUIRED", "STATIC_CHECKS", "WARNING", "Options", "Problem", "_Host",
           "check_fmu", "check_model_description", "check_together", "classify",
           "format_report", "passed"]


@dataclass
class Options:
    """Knobs of :func:`check_fmu`."""

    # True: project conventions and the standard's recommendations are errors (our FMUs);
    # False (--lenient): only what FMI 2.0.4 requires is an error, the rest warnings
    strict: bool = True
    step_tolerance: float = 1e-9  # variable-step results vs fixed-step results (relative)
    n_steps: int = 40  # communication steps per run
    # CPU s one FMI call may use (set-up calls: at least setup_call_timeout); a call that uses
    # no CPU hangs once the machine, at its measured speed, offered it twice that
    # (cosim.interop.compliance.watchdog)
    call_timeout: float = 5.0
    setup_call_timeout: float = SETUP_CALL_ALLOWANCE
    # s of a free core (wall-clock time times the measured share of a core) for all the
    # dynamic checks of one FMU, worker restarts included
    timeout: float = 300.0
    # outputs (fnmatch on name, or "description:<pattern>") excluded from the exact
    # reproducibility comparisons (reset, state, instances): wall-clock measurements
    irreproducible: tuple[str, ...] = ("*wall_time*", "*solve_time*", "*cpu_time*",
                                       "description:*wall-clock*")
    # outputs excluded only from the variable-step comparison: defined per communication step
    step_dependent: tuple[str, ...] = ("description:*communication step*",)
    dynamic: bool = True
    # extracted size, file count, modelDescription size (checked before anything is read)
    limits: ArchiveLimits = field(default_factory=ArchiveLimits)


def _limits(opts: Options) -> Limits:
    return Limits(call_cpu=opts.call_timeout, setup_call_cpu=opts.setup_call_timeout,
                  budget=opts.timeout)


def _worker_options(opts: Options) -> dict[str, Any]:
    return {"n_steps": opts.n_steps, "step_tolerance": opts.step_tolerance,
            "limits": asdict(opts.limits),
            "irreproducible": list(opts.irreproducible),
            "step_dependent": list(opts.step_dependent)}


def check_fmu(path: str | Path, options: Options | None = None) -> list[Problem]:
    """All compliance checks of one FMU file, each finding with its FMI 2.0.4 clause and
    requirement; an empty list (or only warnings/notes) passes."""
    opts = options or Options()
    path = Path(path)
    if not path.is_file():
        return [Problem("fmpy-validation", f"{path}: no such file")]
    try:
        inspect(path, opts.limits)
    except ArchiveRefused as err:
        return skipped(ALL_CHECKS, "the archive was refused",
                       [Problem("fmpy-validation", f"archive refused before extraction: {err}")])
    except (zipfile.BadZipFile, OSError):
        pass  # reported by the static checks (not a readable zip archive)
    if fmi_version(path, opts.limits.max_model_description) == "3.0":
        return _check_fmi3(path, opts)
    problems = check_model_description(path, strict=opts.strict)
    if not opts.dynamic:
        return problems
    loadable = not any(p.check in ("variables", "capabilities") and "unreadable" in p.message
                       or p.message == "not a co-simulation FMU"
                       or p.severity == SKIPPED for p in problems)
    if not loadable:
        return skipped(DYNAMIC_CHECKS, "the FMU could not be read or is not for "
                       "co-simulation", problems)
    args = {"mode": "single", "paths": [str(path.resolve())], **_worker_options(opts)}
    return classify(problems + _run_worker(args, DYNAMIC_CHECKS, _limits(opts)), opts.strict)


def fmi_version(path: Path, max_bytes: int | None = None) -> str | None:
    """The fmiVersion attribute of an FMU's modelDescription.xml (None if unreadable or larger
    than ``max_bytes``, default :class:`ArchiveLimits`' limit)."""
    try:
        limit = ArchiveLimits().max_model_description if max_bytes is None else max_bytes
        return _read_xml(path, limit).get("fmiVersion")
    except Exception:
        return None


def checks_for(path: str | Path) -> tuple[str, ...]:
    """The checks :func:`check_fmu` runs on this FMU (FMI 2.0 or FMI 3.0 ones)."""
    return FMI3_CHECKS if fmi_version(Path(path)) == "3.0" else ALL_CHECKS


def _check_fmi3(path: Path, opts: Options) -> list[Problem]:
    """The FMI 3.0 checks (:mod:`cosim.interop.compliance.fmi3`)."""
    problems = static_checks(path) + clock_checks(path)
    if not opts.dynamic:
        return classify(problems, opts.strict)
    runnable = not any(p.check == "fmi3-capabilities" and p.severity != NOTE
                       or p.severity == SKIPPED for p in problems)
    if not runnable:
        return classify(skipped(FMI3_DYNAMIC_CHECKS, "the FMU cannot be run here (see "
                                "fmi3-capabilities)", problems), opts.strict)
    args = {"mode": "fmi3", "paths": [str(path.resolve())], **_worker_options(opts)}
    return classify(problems + _run_worker(args, FMI3_DYNAMIC_CHECKS, _limits(opts)),
                    opts.strict)


def check_together(paths: list[str | Path], options: Options | None = None) -> list[Problem]:
    """Load all ``paths`` in one process and check each runs as it does alone."""
    opts = options or Options()
    args = {"mode": "together", "paths": [str(Path(p).resolve()) for p in paths],
            **_worker_options(opts)}
    return classify(_run_worker(args, ("together",), _limits(opts)), opts.strict)


def format_report(path: str | Path, problems: list[Problem],
                  checks: tuple[str, ...] | None = None) -> str:
    """A readable report: one line per check (ok / FAIL / warn) with the FMI 2.0.4 clause it
    enforces, then the findings (with what they rest on when the standard does not require
    it: ``recommended`` or a project ``convention``)."""
    if checks is None:  # an FMU with no finding at all is listed by its fmiVersion
        fmi3 = (any(p.check in FMI3_CHECKS for p in problems)
                or Path(path).is_file() and fmi_version(Path(path)) == "3.0")
        checks = FMI3_CHECKS if fmi3 else ALL_CHECKS
    lines = [f"FMU {path}"]
    by_check: dict[str, list[Problem]] = {}
    for p in problems:
        by_check.setdefault(p.check, []).append(p)
    for check in [*checks, *[c for c in by_check if c not in checks]]:
        found = by_check.get(check, [])
        severities = {p.severity for p in found}
        label = ("FAIL" if ERROR in severities else "warn" if WARNING in severities
                 else "skip" if SKIPPED in severities else "ok")
        clause = CLAUSES.get(check, ("", ""))[0]
        if label == "skip":
            reason = next(p.message for p in found if p.severity == SKIPPED)
            lines.append(f"  {label:<4}  {check:<20}  ({reason.removeprefix('not run: ')})")
            continue
        lines.append(f"  {label:<4}  {check:<21}"
                     + (f"  [{standard_of(check)} {clause}]" if clause else ""))
        for p in found:
            if p.severity == SKIPPED:
                continue
            basis = f" ({p.requirement})" if p.requirement not in ("", REQUIRED) else ""
            lines.append(f"          {p.severity}{basis}: {p.message}")
    n_err = sum(p.severity == ERROR for p in problems)
    n_warn = sum(p.severity == WARNING for p in problems)
    n_skip = len({p.check for p in problems if p.severity == SKIPPED})
    verdict = "PASSED" if n_err == 0 else "FAILED"
    lines.append(f"  {verdict}: {n_err} error(s), {n_warn} warning(s)"
                 + (f", {n_skip} check(s) skipped" if n_skip else ""))
    return "\n".join(lines)
