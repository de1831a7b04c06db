"""The parts import one way (issue 8, docs/architecture.md):

    cosim.fmu  <-  plants  <-  controllers
        ^                         (plants and controllers use cosim's FMU side, never the reverse)
    cosim.run  <-  cosim.interop  <-  cosim.cli
        ^    ^
        |    cosim.reproduce  <-  cosim.cli  (paper reproductions: entries, jobs, tables, page)
    cosim.papers  (paper metrics; cosim.run consults their registry by module name, importlib)
    plants  <-  cosim.optimal  <-  cosim.cli  (offline planning on the plants' physics)

``cosim.fmu`` (bundled into every FMU) imports nothing else of the project; ``cosim.run`` and
``cosim.interop`` never import plants or controllers (the catalog finds the FMU wrappers by
file name, not by import). The modules of ``cosim.run`` that evaluate a reproduction's record
(:data:`ALSO_ALLOWED`) also import ``cosim.reproduce``. Checked on the import statements of
every module (``ast``).
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent

# part -> the parts it may import (itself included)
ALLOWED: dict[str, set[str]] = {
    "cosim.fmu": {"cosim.fmu"},
    "plants": {"cosim.fmu", "plants"},
    "controllers": {"cosim.fmu", "plants", "controllers"},
    "cosim.run": {"cosim.fmu", "cosim.run"},
    "cosim.papers": {"cosim.fmu", "cosim.run", "cosim.papers"},
    "cosim.interop": {"cosim.fmu", "cosim.run", "cosim.interop"},
    "cosim.optimal": {"cosim.fmu", "plants", "cosim.optimal"},
    "cosim.reproduce": {"cosim.fmu", "cosim.run", "cosim.reproduce"},
    "cosim.cli": {"cosim.fmu", "cosim.run", "cosim.papers", "cosim.interop", "cosim.optimal",
                  "cosim.reproduce", "cosim.cli"},
    # the Python entry point: a peer of the CLI (it reads the CLI's choice of printed metrics)
    "cosim.api": {"cosim.fmu", "cosim.run", "cosim.cli", "cosim.api"},
    "cosim": {"cosim"},  # cosim/__init__.py: nothing
}
# module -> the parts it may import besides its part's: the claims' ensembles and the pages
# evaluate a reproduction's record with the reproduction's helpers (evaluation-only modules)
ALSO_ALLOWED: dict[str, set[str]] = {
    "cosim.run.ensemble": {"cosim.reproduce"},
    "cosim.run.docs_pages": {"cosim.reproduce"},
}


def part_of(module: str) -> str | None:
    for part in sorted(ALLOWED, key=len, reverse=True):
        if module == part or module.startswith(part + "."):
            return part
    return None


def project_imports(path: Path, module: str) -> list[tuple[int, str]]:
    tree = ast.parse(path.read_text(), filename=str(path))
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join(anchor + ([base] if base else []))
            names = [base]
        else:
            continue
        found += [(node.lineno, n) for n in names if part_of(n) is not None]
    return found


def modules() -> list[tuple[Path, str]]:
    out = []
    for top in ("cosim", "plants", "controllers"):
        for path in sorted((ROOT / top).rglob("*.py")):
            rel = path.relative_to(ROOT).with_suffix("")
            parts = rel.parts[:-1] if rel.name == "__init__" else rel.parts
            out.append((path, ".".join(parts)))
    return out


@pytest.mark.parametrize(("path", "module"), modules(), ids=lambda x: str(x))
def test_imports_run_one_way(path: Path, module: str) -> None:
    own = part_of(module)
    assert own is not None, f"{module} belongs to no part: add it to ALLOWED"
    for line, imported in project_imports(path, module):
        assert part_of(imported) in ALLOWED[own] | ALSO_ALLOWED.get(module, set()), (
            f"{path.relative_to(ROOT)}:{line}: {own} must not import {imported}")


def test_the_checker_catches_an_upward_import(tmp_path: Path) -> None:
    bad = tmp_path / "metrics.py"
    bad.write_text("from plants.route import Route\nfrom . import master\n")
    imports = project_imports(bad, "cosim.run.metrics")
    assert [part_of(m) for _, m in imports] == ["plants", "cosim.run"]
    assert "plants" not in ALLOWED["cosim.run"]
