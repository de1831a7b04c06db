"""Shared vocabulary of the compliance checks: severities, check names, :class:`Problem`,
and small readers of the modelDescription."""

from __future__ import annotations

import zipfile
from dataclasses import dataclass
from pathlib import Path
from xml.etree import ElementTree

ERROR, WARNING, NOTE = "error", "warning", "note"

STATIC_CHECKS = ("fmpy-validation", "variables", "units", "model-structure",
                 "default-experiment", "capabilities")
DYNAMIC_CHECKS = ("calling-sequence", "output-dependencies", "reset", "fmu-state",
                  "variable-step", "two-instances", "wrong-state", "invalid-step",
                  "non-finite-inputs", "bad-parameters")
ALL_CHECKS = STATIC_CHECKS + DYNAMIC_CHECKS

_FATAL = "rejected with fmi2Fatal, expected fmi2Error"
_MARK = "@@compliance "  # worker protocol lines on stdout (the FMU may print too)


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

