"""The parts import one way (issue 8, docs/architecture.md):

    cosim.fmu  <-  plants  <-  controllers
        ^                         (plants and controllers use cosim's FMU side, never the reverse)
    cosim.build  (the builders and the catalog, above the cores: bundled into no FMU)
        ^
    cosim.run  <-  cosim.interop  <-  cosim.cli
        ^    ^
        |    cosim.reproduce  <-  cosim.site  <-  cosim.cli  (reproductions; the generated pages)
    cosim.papers  (the metric registry; cosim.run consults it by module name, importlib)
        ^
    papers/NAME/metrics.py  (a paper's metric plug-ins; only the registry loads them, by path)
    plants  <-  cosim.optimal  <-  cosim.cli  (offline planning on the plants' physics)

A paper's folder ``papers/NAME/`` holds its metric plug-ins (``metrics.py``, checked as module
``papers.NAME.metrics``: it imports ``cosim.fmu``, ``cosim.run`` and ``cosim.papers`` only) and
its scripts (tuning, route and data: top-level programs like ``benchmarks/``, which may import
the project) and its tests (``papers/NAME/tests/``, in the suite's ``testpaths``); no module,
script or test imports a paper's folder (the registry loads the metrics by path, tests load a
script by path). A paper's tests import the library (``cosim``, ``plants``, ``controllers``),
the shared test helpers (``tests.NAME``; the shared fixtures are the root ``conftest.py``'s)
and their own folder's modules; nothing outside the paper's folder imports them.

``cosim.fmu`` (bundled into every FMU) imports nothing else of the project; ``cosim.build``
(the builders) stands above the cores: it may import ``cosim.fmu``, ``plants`` and
``controllers``, in import statements (only the catalog loads modules by name, the wrappers it
finds by file name: :data:`LOADS_BY_NAME`), each core's build-time data for C coming from the
core's own ``native_data`` through the catalog; ``cosim.run`` and
``cosim.interop`` never import plants or controllers (the catalog finds the FMU wrappers by
file name, not by import); what evaluates a reproduction's record (its claims, statistics,
record, tables and page) is ``cosim.reproduce``, above ``cosim.run``. Checked on the import
statements of every module (``ast``), those inside functions included.

No module of ``cosim`` imports, directly or through others, a module that imports it: the
graph of every import statement (module-level and function-local; those under ``if
TYPE_CHECKING:`` only, which never run, left out) has no cycle. An import moved into a function
still counts, so a cycle is cut by moving the shared piece down or passing it in. Project
modules are imported at module level; only ``cosim/cli.py`` imports them inside functions (so
``cosim --help`` starts without loading the runners).
"""

from __future__ import annotations

import ast
import functools
import graphlib
from collections import deque
from pathlib import Path
from typing import NamedTuple

import pytest

ROOT = Path(__file__).resolve().parent.parent

# part -> the parts it may import (itself included)
ALLOWED: dict[str, set[str]] = {
    "cosim.fmu": {"cosim.fmu"},
    "plants": {"cosim.fmu", "plants"},
    "controllers": {"cosim.fmu", "plants", "controllers"},
    "cosim.build": {"cosim.fmu", "plants", "controllers", "cosim.build"},
    "cosim.run": {"cosim.fmu", "cosim.build", "cosim.run"},
    "cosim.papers": {"cosim.fmu", "cosim.run", "cosim.papers"},
    "cosim.interop": {"cosim.fmu", "cosim.run", "cosim.interop"},
    "cosim.optimal": {"cosim.fmu", "plants", "cosim.optimal"},
    "cosim.reproduce": {"cosim.fmu", "cosim.build", "cosim.run", "cosim.reproduce"},
    # the documentation site's generated pages: the FMU reference, the schema, the papers
    "cosim.site": {"cosim.fmu", "cosim.build", "cosim.run", "cosim.reproduce", "cosim.site"},
    "cosim.cli": {"cosim.fmu", "cosim.build", "cosim.run", "cosim.papers", "cosim.interop",
                  "cosim.optimal", "cosim.reproduce", "cosim.site", "cosim.cli"},
    # the Python entry point: a peer of the CLI (it reads the CLI's choice of printed metrics)
    "cosim.api": {"cosim.fmu", "cosim.run", "cosim.cli", "cosim.api"},
    "cosim": {"cosim"},  # cosim/__init__.py: nothing
    # a paper's metric plug-ins (papers/NAME/metrics.py): the registry and what a metric reads
    "papers": {"cosim.fmu", "cosim.run", "cosim.papers"},
}


class ImportStatement(NamedTuple):
    node: ast.Import | ast.ImportFrom
    in_function: bool  # inside a function (def or async def), at any depth
    type_checking_only: bool  # in the body of an ``if TYPE_CHECKING:``, at any depth


def import_statements(path: Path) -> tuple[ImportStatement, ...]:
    """The import statements of ``path`` in ``ast.walk`` order (:func:`_import_statements`),
    read each time and parsed once per text."""
    return _import_statements(path.read_text(), str(path))


@functools.cache
def _import_statements(source: str, filename: str) -> tuple[ImportStatement, ...]:
    """One breadth-first walk of the tree (``ast.walk``'s order), each node carrying whether
    a function encloses it and whether the body of an ``if TYPE_CHECKING:`` (a block that
    never runs: annotations only) does; only the import statements are kept, not the tree."""
    found = []
    todo = deque([(ast.parse(source, filename=filename), False, False)])
    while todo:
        node, in_function, checking = todo.popleft()
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            found.append(ImportStatement(node, in_function, checking))
        in_function = in_function or isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef))
        body = (node.body if isinstance(node, ast.If) and isinstance(node.test, ast.Name)
                and node.test.id == "TYPE_CHECKING" else [])
        todo.extend((child, in_function, checking or any(child is b for b in body))
                    for child in ast.iter_child_nodes(node))
    return tuple(found)


def part_of(module: str) -> str | None:
    for part in sorted(ALLOWED, key=len, reverse=True):
        if module == part or module.startswith(part + "."):
            return part
    return None


def project_imports(path: Path, module: str) -> list[tuple[int, str]]:
    return [(line, name) for line, name, _ in _imports(module, path)]


def modules() -> list[tuple[Path, str]]:
    out = []
    for top in ("cosim", "plants", "controllers"):
        for path in sorted((ROOT / top).rglob("*.py")):
            rel = path.relative_to(ROOT).with_suffix("")
            parts = rel.parts[:-1] if rel.name == "__init__" else rel.parts
            out.append((path, ".".join(parts)))
    for path in sorted((ROOT / "papers").glob("*/metrics.py")):  # loaded by the registry
        out.append((path, f"papers.{path.parent.name}.metrics"))
    return out


def scripts() -> list[Path]:
    """Every Python file that is not a module of :func:`modules`: the benchmarks, the tests
    (``tests/``, the papers' ``papers/NAME/tests/`` and the shared fixtures, ``conftest.py``)
    and the papers' scripts (tuning, route and data)."""
    listed = {path for path, _ in modules()}
    return sorted([path for top in ("benchmarks", "tests", "papers")
                   for path in (ROOT / top).rglob("*.py") if path not in listed]
                  + [ROOT / "conftest.py"])


@pytest.mark.parametrize("path", [p for p, _ in modules()] + scripts(),
                         ids=lambda p: str(p.relative_to(ROOT)))
def test_nothing_imports_a_paper_folder(path: Path) -> None:
    """A paper's folder is loaded (its metrics by the registry, a script by path), never
    imported: no import statement anywhere names ``papers``."""
    for node, _, _ in import_statements(path):
        names = ([a.name for a in node.names] if isinstance(node, ast.Import)
                 else [node.module or ""] if isinstance(node, ast.ImportFrom) and not node.level
                 else [])
        assert not any(n == "papers" or n.startswith("papers.") for n in names), (
            f"{path.relative_to(ROOT)}:{node.lineno}: imports {names}: load a paper's "
            "metrics through cosim.papers (paper_metrics), a script by its path")


# what a paper's tests may import of the project, besides their own folder's modules
PAPER_TESTS_IMPORT = {"cosim", "plants", "controllers", "tests"}


def paper_test_files() -> dict[Path, list[Path]]:
    """A paper's tests folder (``papers/NAME/tests``) -> its Python files."""
    return {folder: sorted(folder.rglob("*.py"))
            for folder in sorted((ROOT / "papers").glob("*/tests")) if folder.is_dir()}


def imported_names(path: Path) -> list[tuple[int, str]]:
    """The absolute imports of ``path``: (line, dotted name), ``from a import b`` giving
    ``a`` and ``a.b``."""
    found = []
    for node, _, _ in import_statements(path):
        if isinstance(node, ast.Import):
            found += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom) and not node.level and node.module:
            found += [(node.lineno, node.module)]
            found += [(node.lineno, f"{node.module}.{a.name}") for a in node.names]
    return found


def paper_test_import_problems(path: Path, own: set[str], helpers: set[str],
                               project: set[str]) -> list[str]:
    """What a paper's test file ``path`` imports of the project beyond the library, the shared
    helpers (``tests.NAME``) and ``own`` (its folder's module names): bare helper names too
    (``tests/`` is on ``sys.path`` only when a test there ran first)."""
    problems = []
    for line, name in imported_names(path):
        top = name.split(".")[0]
        if top in own or top in PAPER_TESTS_IMPORT:
            continue
        if top in project or top in helpers:
            shown = path.relative_to(ROOT) if ROOT in path.parents else path
            problems.append(f"{shown}:{line}: imports {name}")
    return problems


PROJECT_TOPS = {"cosim", "plants", "controllers", "tests", "papers", "benchmarks", "conftest"}


@pytest.mark.parametrize("folder", list(paper_test_files()),
                         ids=lambda p: str(p.relative_to(ROOT)))
def test_a_papers_tests_import_the_library_and_the_shared_helpers(folder: Path) -> None:
    """``papers/NAME/tests/*.py`` import ``cosim``, ``plants``, ``controllers``, the shared
    helpers as ``tests.NAME`` and their own folder's modules, nothing else of the project."""
    helpers = {p.stem for p in (ROOT / "tests").rglob("*.py")}
    own = {p.stem for p in paper_test_files()[folder]}
    for path in paper_test_files()[folder]:
        problems = paper_test_import_problems(path, own, helpers, PROJECT_TOPS)
        assert not problems, "; ".join(problems) + (
            ": a paper's tests import the library and the shared test helpers (tests.NAME)")


def test_nothing_outside_a_papers_folder_imports_its_tests() -> None:
    """No module or script outside ``papers/NAME/`` imports a module of its ``tests/`` (by its
    name: the suite's import mode puts each test's folder on ``sys.path``)."""
    folders = paper_test_files()
    assert folders, "no paper has a tests folder"
    tests_of = {folder: {p.stem for p in files} for folder, files in folders.items()}
    for path in [p for p, _ in modules()] + scripts():
        imports = imported_names(path)  # each file parsed once
        for folder, names in tests_of.items():
            if folder.parent in path.parents:
                continue  # the paper's own folder
            for line, name in imports:
                assert not set(name.split(".")) & names, (
                    f"{path.relative_to(ROOT)}:{line}: imports {name}, a test of "
                    f"{folder.relative_to(ROOT)}: a paper's tests are its own")


def test_the_paper_test_checker_catches_a_bare_helper_and_another_papers_test(
        tmp_path: Path) -> None:
    code = tmp_path / "test_x.py"
    code.write_text("from tests.claim_rows import claim_row\nfrom claim_rows import claim_row\n"
                    "import benchmarks.run_all\nfrom cosim import papers\nimport numpy\n"
                    "from test_y import helper\n")
    problems = paper_test_import_problems(code, {"test_x", "test_y"}, {"claim_rows"},
                                          PROJECT_TOPS)
    assert [p.rsplit(": ", 1)[1] for p in problems] == [
        "imports claim_rows", "imports claim_rows.claim_row", "imports benchmarks.run_all"]


@pytest.mark.parametrize(("path", "module"), modules(), ids=lambda x: str(x))
def test_imports_run_one_way(path: Path, module: str) -> None:
    own = part_of(module)
    assert own is not None, f"{module} belongs to no part: add it to ALLOWED"
    for line, imported in project_imports(path, module):
        assert part_of(imported) in ALLOWED[own], (
            f"{path.relative_to(ROOT)}:{line}: {own} must not import {imported}")


# module of cosim.build -> why it loads modules by name: the catalog, on purpose
LOADS_BY_NAME = {"cosim.build.python": "the catalog imports the wrappers it finds by file name "
                                       "(**/*_fmu.py), and a built FMU's entry imports its bundle"}


def test_the_builder_stands_above_the_cores_in_its_imports() -> None:
    """The builders belong to ``cosim.build``: the route data the native builder exports come
    from ``plants`` in an import statement the checker reads, no module but the catalog's
    loads a module by name (``importlib.import_module``, ``__import__``), and neither the FMU
    layer nor a core imports the builders."""
    built = [(path, module) for path, module in modules() if part_of(module) == "cosim.build"]
    assert {"cosim.build", "cosim.build.native", "cosim.build.solvers", "cosim.build.python",
            "cosim.build.fmi3", "cosim.build.reference"} <= {module for _, module in built}
    native = ROOT / "cosim" / "build" / "native.py"
    assert {part_of(m) for _, m in project_imports(native, "cosim.build.native")} == {
        "cosim.fmu", "plants", "cosim.build"}
    for path, module in built:
        if module in LOADS_BY_NAME:
            continue
        tree = ast.parse(path.read_text(), filename=str(path))
        called = {node.func.attr if isinstance(node.func, ast.Attribute) else node.func.id
                  for node in ast.walk(tree) if isinstance(node, ast.Call)
                  and isinstance(node.func, (ast.Attribute, ast.Name))}
        assert not called & {"import_module", "__import__"}, (
            f"{path.relative_to(ROOT)} loads a module by name")
    assert all("cosim.build" not in ALLOWED[part] for part in ("cosim.fmu", "plants",
                                                               "controllers"))


def test_the_checker_catches_an_upward_import(tmp_path: Path) -> None:
    bad = tmp_path / "metrics.py"
    bad.write_text("from plants.route import Route\nfrom . import master\n")
    imports = project_imports(bad, "cosim.run.metrics")
    assert [part_of(m) for _, m in imports] == ["plants", "cosim.run"]
    assert "plants" not in ALLOWED["cosim.run"]


def imported_modules(path: Path, module: str, known: set[str]) -> set[str]:
    """The project modules ``path`` (module ``module``) imports at run time, anywhere in it:
    ``from package import submodule`` names the submodule, ``from module import name`` the
    module."""
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    found: set[str] = set()
    for node, _, checking in import_statements(path):
        if checking:  # under ``if TYPE_CHECKING:`` only (annotations)
            continue
        if isinstance(node, ast.Import):
            found |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join(anchor + ([base] if base else []))
            found |= {f"{base}.{a.name}" if f"{base}.{a.name}" in known else base
                      for a in node.names}
    return (found & known) - {module}


def import_graph(tops: tuple[str, ...] = ("cosim", "papers")) -> dict[str, set[str]]:
    """Module -> the project modules it imports, over every module under ``tops`` (cosim and
    the papers' metric plug-ins)."""
    found = [(path, module) for path, module in modules() if module.split(".")[0] in tops]
    known = {module for _, module in found}
    return {module: imported_modules(path, module, known) for path, module in found}


def cycle_of(graph: dict[str, set[str]]) -> list[str] | None:
    """One import cycle of ``graph`` (its modules, the first repeated last), None without."""
    try:
        tuple(graphlib.TopologicalSorter(graph).static_order())
    except graphlib.CycleError as err:
        return list(err.args[1])
    return None


def test_no_import_cycle_in_cosim() -> None:
    cycle = cycle_of(import_graph())
    assert cycle is None, f"import cycle: {' -> '.join(cycle or [])}"


def test_the_cycle_check_sees_function_local_imports(tmp_path: Path) -> None:
    (tmp_path / "a.py").write_text("from cosim.run import b\n")
    (tmp_path / "b.py").write_text("def f():\n    from cosim.run.a import g\n")
    (tmp_path / "c.py").write_text(
        "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from cosim.run.a import g\n")
    known = {"cosim.run.a", "cosim.run.b", "cosim.run.c"}
    graph = {m: imported_modules(tmp_path / f"{m[-1]}.py", m, known) for m in known}
    assert graph == {"cosim.run.a": {"cosim.run.b"}, "cosim.run.b": {"cosim.run.a"},
                     "cosim.run.c": set()}
    assert set(cycle_of(graph) or []) == {"cosim.run.a", "cosim.run.b"}
    assert cycle_of({**graph, "cosim.run.b": set()}) is None


# module -> why it imports project modules inside functions: the command line, on purpose
LAZY_ALLOWED = {"cosim.cli": "start-up time: `cosim --help` loads no runner"}


def function_local_imports(path: Path, module: str) -> list[tuple[int, str]]:
    """The project imports inside the functions of ``path`` (line, module imported)."""
    return [(line, name) for line, name, inside in _imports(module, path) if inside]


def _imports(module: str, path: Path) -> list[tuple[int, str, bool]]:
    """(line, project module, whether inside a function) of each import of ``path``."""
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    found = []
    for node, in_function, _ in import_statements(path):
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
        found += [(node.lineno, n, in_function) for n in names if part_of(n) is not None]
    return found


COSIM_MODULES = [(path, module) for path, module in modules() if module.split(".")[0] == "cosim"]


@pytest.mark.parametrize(("path", "module"), COSIM_MODULES, ids=lambda x: str(x))
def test_only_the_cli_imports_project_modules_inside_functions(path: Path, module: str
                                                              ) -> None:
    lazy = function_local_imports(path, module)
    if module in LAZY_ALLOWED:
        return
    assert not lazy, (f"{path.relative_to(ROOT)}:{lazy[0][0]}: {lazy[0][1]} imported inside a "
                      "function: import it at module level (only cosim/cli.py imports lazily)")


def test_the_lazy_import_check_sees_imports_inside_functions(tmp_path: Path) -> None:
    code = tmp_path / "m.py"
    code.write_text("from cosim.run import exchange\n\ndef f():\n"
                    "    from cosim.run.scenario import load_scenario\n    import json\n")
    assert function_local_imports(code, "cosim.run.m") == [(4, "cosim.run.scenario")]
