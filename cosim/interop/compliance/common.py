"""Shared vocabulary of the compliance checks: severities, check names, :class:`Problem`,
and small readers of the modelDescription."""

from __future__ import annotations

import zipfile
from dataclasses import dataclass, replace
from pathlib import Path
from xml.etree import ElementTree

from cosim.run.archive import ArchiveRefused

ERROR, WARNING, NOTE = "error", "warning", "note"
SKIPPED = "skipped"  # a check that could not run (never reported as "ok")

STATIC_CHECKS = ("fmpy-validation", "variables", "units", "model-structure",
                 "default-experiment", "capabilities")
DYNAMIC_CHECKS = ("calling-sequence", "output-dependencies", "reset", "fmu-state",
                  "variable-step", "two-instances", "wrong-state", "invalid-step",
                  "non-finite-inputs", "bad-parameters")
ALL_CHECKS = STATIC_CHECKS + DYNAMIC_CHECKS

# What a finding rests on: the standard's "shall" (an error everywhere), its recommendation or
# a behaviour it leaves to the FMU (a warning under --lenient), or a project convention (ours
# keep it; a warning under --lenient).
REQUIRED, RECOMMENDED, CONVENTION = "required", "recommended", "convention"

# check -> (FMI 2.0.4 clause it enforces, requirement of its findings unless a finding says
# otherwise)
CLAUSES: dict[str, tuple[str, str]] = {
    "fmpy-validation": ("2.2 (modelDescription schema and rules)", REQUIRED),
    "variables": ("2.2.7 (causality/variability/initial, start, min <= start <= max)",
                  REQUIRED),
    "units": ("2.2.2 (units of variables are defined in UnitDefinitions)", REQUIRED),
    "model-structure": ("2.2.8 (every output listed in ModelStructure/Outputs)", REQUIRED),
    "default-experiment": ("2.2.5 (DefaultExperiment is optional)", CONVENTION),
    "capabilities": ("4.3.1 (co-simulation capability flags)", REQUIRED),
    "calling-sequence": ("4.2.4 (the calling sequence of a co-simulation slave)", REQUIRED),
    "output-dependencies": ("2.2.8 (an output depends on no input it does not list)",
                            REQUIRED),
    "reset": ("2.1.6 (fmi2Reset returns the FMU to its state after instantiation)", REQUIRED),
    "fmu-state": ("2.1.8 (fmi2Get/SetFMUstate and serialisation restore the FMU state)",
                  REQUIRED),
    "variable-step": ("4.2.2 (fmi2DoStep; equal results for split steps is a convention)",
                      CONVENTION),
    "two-instances": ("2.1.5 (instances of one FMU are independent)", REQUIRED),
    "wrong-state": ("4.2.4 (calls outside the state machine are the master's error; an FMU "
                    "should detect them)", RECOMMENDED),
    "invalid-step": ("4.2.2 (communicationStepSize > 0; an FMU should reject others)",
                     RECOMMENDED),
    "non-finite-inputs": ("2.1.7 (checking input values is left to the FMU)", RECOMMENDED),
    "bad-parameters": ("2.2.7 (min/max bound the values a master may set; checking them is "
                       "left to the FMU)", RECOMMENDED),
    "together": ("2.1.5 (instances of several FMUs in one process are independent)",
                 REQUIRED),
}

FMI3_STATIC_CHECKS = ("fmi3-validation", "fmi3-variables", "fmi3-model-structure",
                      "fmi3-capabilities", "fmi3-clocks")
# the dynamic checks of the co-simulation interface (not applicable to an FMU without one)
FMI3_CS_CHECKS = ("fmi3-calling-sequence", "fmi3-event-mode", "fmi3-early-return",
                  "fmi3-fmu-state", "fmi3-wrong-state")
FMI3_DYNAMIC_CHECKS = (*FMI3_CS_CHECKS, "fmi3-clock-calls", "fmi3-scheduled-execution",
                       "fmi3-scheduled-wrong-state")
FMI3_CHECKS = FMI3_STATIC_CHECKS + FMI3_DYNAMIC_CHECKS

# check -> (FMI 3.0 clause, requirement of its findings unless a finding says otherwise)
FMI3_CLAUSES: dict[str, tuple[str, str]] = {
    "fmi3-validation": ("2.4 (FMI Description Schema, modelDescription rules)", REQUIRED),
    "fmi3-variables": ("2.4.7 (ModelVariables: causality, variability, initial, start, "
                       "min/max, units; exactly one independent variable)", REQUIRED),
    "fmi3-model-structure": ("2.4.8 (ModelStructure: every output listed as Output)",
                             REQUIRED),
    "fmi3-capabilities": ("4.4 (the CoSimulation element) and 2.5.1.4 (binaries/<platform>)",
                          REQUIRED),
    "fmi3-calling-sequence": ("4.2 (co-simulation state machine: instantiate, initialise, "
                              "fmi3DoStep, terminate)", REQUIRED),
    "fmi3-event-mode": ("2.3.5, 4.2.1 (Event Mode: fmi3UpdateDiscreteStates, nextEventTime, "
                        "eventHandlingNeeded)", REQUIRED),
    "fmi3-early-return": ("4.1.3, 4.2.1 (fmi3DoStep earlyReturn, lastSuccessfulTime; "
                          "mightReturnEarlyFromDoStep)", REQUIRED),
    "fmi3-fmu-state": ("2.2.7.4 (fmi3Get/SetFMUState, serialisation restore the FMU state)",
                       REQUIRED),
    "fmi3-wrong-state": ("4.2 (calls outside the state machine are the importer's error; an "
                         "FMU should detect them)", RECOMMENDED),
    "fmi3-clocks": ("2.2.8 (Clocks), 2.4.4 (ClockType attributes), 2.4.7.4 (clocks, previous), "
                    "2.4.8 (ClockedState)", REQUIRED),
    "fmi3-clock-calls": ("2.2.8.2 (Clock Types: fmi3GetInterval/GetShift in Initialization "
                         "Mode, fmi3SetClock and fmi3GetClock in Event Mode)", REQUIRED),
    "fmi3-scheduled-execution": ("5.2 (Scheduled Execution: fmi3ActivateModelPartition at "
                                 "the Clocks' ticks, Clock Update Mode)", REQUIRED),
    "fmi3-scheduled-wrong-state": ("5.2.1, 2.2.8.4 (calls outside the Scheduled Execution "
                                   "state machine are the importer's error; an FMU should "
                                   "detect them)", RECOMMENDED),
}

CLAUSES.update(FMI3_CLAUSES)


def standard_of(check: str) -> str:
    """The standard (and edition) a check's clause refers to."""
    return "FMI 3.0" if check in FMI3_CLAUSES else "FMI 2.0.4"


_FATAL = "rejected with fmi2Fatal, expected fmi2Error"
_MARK = "@@compliance "  # worker protocol lines on stdout (the FMU may print too)


@dataclass(frozen=True)
class Problem:
    """One finding: the check it belongs to, a readable message, its severity."""

    check: str
    message: str
    severity: str = ERROR
    requirement: str = ""  # REQUIRED / RECOMMENDED / CONVENTION; "" = the check's
    clause: str = ""  # FMI 2.0.4 clause; "" = the check's

    def __str__(self) -> str:
        return f"[{self.severity}] {self.check}: {self.message}"


def classify(problems: list[Problem], strict: bool) -> list[Problem]:
    """Fill in clause and requirement; unless ``strict``, an error that is not required by
    the standard becomes a warning (``cosim validate --lenient``)."""
    out = []
    for p in problems:
        clause, requirement = CLAUSES.get(p.check, ("", REQUIRED))
        p = replace(p, clause=p.clause or clause, requirement=p.requirement or requirement)
        if not strict and p.severity == ERROR and p.requirement != REQUIRED:
            p = replace(p, severity=WARNING)
        out.append(p)
    return out


def skipped(checks: tuple[str, ...], reason: str, problems: list[Problem]) -> list[Problem]:
    """``problems`` plus a "skipped" entry for each of ``checks`` that has no finding."""
    seen = {p.check for p in problems}
    return [*problems, *(Problem(c, f"not run: {reason}", SKIPPED) for c in checks
                         if c not in seen)]


def passed(problems: list[Problem]) -> bool:
    """True when no problem is an error (warnings and notes do not fail)."""
    return not any(p.severity == ERROR for p in problems)


def _read_xml(path: Path, max_bytes: int | None = None) -> ElementTree.Element:
    """The parsed modelDescription.xml (refused over ``max_bytes``; the checks read it after
    :func:`~cosim.run.archive.inspect` bounded it)."""
    with zipfile.ZipFile(path) as z:
        if max_bytes is not None and z.getinfo("modelDescription.xml").file_size > max_bytes:
            raise ArchiveRefused(f"modelDescription.xml is larger than {max_bytes} bytes")
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

