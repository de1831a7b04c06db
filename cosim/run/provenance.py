"""What a reproduction's figures depend on, as one digest (so a generated page knows when it is
stale), and what its simulations depend on, as another (so a record knows when it is).

The inputs of entry ``papers/NAME/entry.toml`` are: the entry itself; every scenario it
names (a string value equal to a shipped scenario's name,
:func:`cosim.run.scenario.scenario_files`); the files of generated
parameter values its runs name (``[[runs]] tuned``); the files bundled into every FMU
those scenarios and the entry name (a string equal to a catalog identifier:
``cosim.build.python.bundled_files`` of its wrapper, i.e. the cores, their data and the FMU layer)
and, on the native build (``cosim reproduce --build native``), for one with a native model
every file that model is made from (``cosim.build.native.native_sources``: its C, the C
fronts and the builder);
and the code that runs and evaluates them (``cosim/run/``, ``cosim/papers/``,
``cosim/reproduce/``: their Python and the master's C loop; every paper's metric plug-ins,
``papers/*/metrics.py``, which the registry loads); the pages' own writer
(:mod:`cosim.site`) is not among them. :func:`entry_digest` is a SHA-256
over their relative paths and contents, so it is the same on every machine for the same tree.

The *simulation* inputs (:func:`simulation_digest`) are the same files less the entry and the
modules that only turn a record into tables, claims, figures and pages (:data:`EVALUATION_ONLY`,
every module of :data:`EVALUATION_ONLY_FOLDERS`):
what fixes a simulation's result given its job (scenario and overrides, which the record keeps
and :func:`cosim.reproduce.record.check_jobs` compares). A record whose simulation digest is the
tree's serves the page whatever changed in the entry or the evaluation code: the page is then
redrawn from it in seconds (``cosim docs``) instead of rerunning the simulations.
"""

from __future__ import annotations

import hashlib
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from cosim.build.native import NATIVE, native_sources
from cosim.build.python import ROOT, bundled_files, catalog
from cosim.run.scenario import entry_files, scenario_files

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib  # type: ignore[no-redef]

EVALUATION = ("cosim/run", "cosim/papers", "cosim/reproduce")
PAPER_METRICS = "papers/*/metrics.py"  # every paper's metric plug-ins (cosim.papers.registry)
INPUTS_FILE = "inputs.sha256"  # in a reproduction's folder: the digest of the inputs it ran
NOT_INPUTS = {"cosim/run/provenance.py"}
# read a record and the entry only: tables, claims, figures, the page
EVALUATION_ONLY = {"cosim/run/console.py"}
# every module under these folders is evaluation-only: the reproduction (its entries, jobs,
# tables, figures and page), whose jobs the record keeps and compares, and every figure
# (a run's, a sweep's, an ensemble's, a paper's), which draws numbers and makes none
EVALUATION_ONLY_FOLDERS = ("cosim/reproduce/", "cosim/run/figures/")


def evaluation_only(relative: str) -> bool:
    """Whether the file at ``relative`` (a POSIX path from the repository root) only evaluates
    a record: one of :data:`EVALUATION_ONLY` or under :data:`EVALUATION_ONLY_FOLDERS`."""
    return relative in EVALUATION_ONLY or relative.startswith(EVALUATION_ONLY_FOLDERS)


def _strings(value: Any) -> Iterator[str]:
    if isinstance(value, str):
        yield value
    elif isinstance(value, dict):
        for item in value.values():
            yield from _strings(item)
    elif isinstance(value, list):
        for item in value:
            yield from _strings(item)


def entry_inputs(name: str, build: str = "python") -> list[Path]:
    """The files entry ``name``'s results on ``build`` (``cosim reproduce --build``) depend on,
    sorted (see the module docstring)."""
    entry = entry_files()[name]
    data = tomllib.loads(entry.read_text())
    known = catalog()
    scenarios = scenario_files()
    files: set[Path] = {entry}
    fmus: set[str] = set()
    for text in set(_strings(data)):
        if "\n" in text or "/" in text or len(text) > 100:  # prose, not a name
            continue
        scenario = scenarios.get(text)
        if scenario is not None:
            files.add(scenario)
            fmus.update(s for s in _strings(tomllib.loads(scenario.read_text())) if s in known)
        if text in known:
            fmus.add(text)
    for run in data.get("runs", []):  # the files of generated parameter values ([[runs]] tuned)
        for ref in run.get("tuned", {}).values():
            path = ROOT / str(ref).partition("#")[0]
            if path.is_file():
                files.add(path)
    for identifier in sorted(fmus):
        files.update(bundled_files(known[identifier].module))
        if build == "native" and identifier in NATIVE:  # its C model, FMI 3 front included
            files.update(native_sources(identifier, 3))
    for folder in EVALUATION:
        for pattern in ("*.py", "*.c"):  # C: the master's compiled loop (native_loop.c)
            for path in (ROOT / folder).rglob(pattern):
                if path.relative_to(ROOT).as_posix() not in NOT_INPUTS:
                    files.add(path)
    files.update(ROOT.glob(PAPER_METRICS))
    return sorted(files)


def simulation_inputs(name: str, build: str = "python") -> list[Path]:
    """:func:`entry_inputs` less the entry itself and the evaluation-only modules
    (:func:`evaluation_only`)."""
    entry = entry_files()[name]
    return [p for p in entry_inputs(name, build)
            if p != entry and not evaluation_only(p.relative_to(ROOT).as_posix())]


def entry_digest(name: str, build: str = "python") -> str:
    """SHA-256 over the relative paths and contents of :func:`entry_inputs`."""
    return _digest(entry_inputs(name, build))


def simulation_digest(name: str, build: str = "python") -> str:
    """SHA-256 over the relative paths and contents of :func:`simulation_inputs`."""
    return _digest(simulation_inputs(name, build))


def _digest(paths: list[Path]) -> str:
    h = hashlib.sha256()
    for path in paths:
        h.update(path.relative_to(ROOT).as_posix().encode() + b"\0")
        h.update(path.read_bytes())
        h.update(b"\0")
    return h.hexdigest()
