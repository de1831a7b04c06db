"""Declare once: FMU variables come from the cores' declarations.

* every built FMU's modelDescription publishes exactly its declarations (name, causality,
  type, unit, range, start, description), and its descriptions say what is, never what was;
* declarations and :func:`build` are inverse, groups flatten, per-configuration values keep;
* no wrapper declares a variable of its own (``docs/fmus.md`` is current: ``cosim docs
  --check``, tests/test_docs_site.py).
"""

from __future__ import annotations

import ast
import dataclasses
import re
from pathlib import Path

import pytest
from fmpy import read_model_description

from cosim.build.python import ROOT, catalog
from cosim.build.reference import REFERENCE_PATH
from cosim.fmu.declare import KEEP, Var, build, group, param, parameters

_TYPES = {float: "Real", int: "Integer", bool: "Boolean", str: "String"}

# narration of the project's past, which belongs in CHANGELOG.md and git, not in what an FMU
# publishes: issue numbers, "was", "no longer", "used to", "(before)", "previously", passes
HISTORY = re.compile(
    r"\bissues? \d+|#\d+|\bwas\b|\bwere\b|\bno longer\b|\bused to\b|\(before\)|\bpreviously\b"
    r"|\bformerly\b|\bunused\b|\bsince (issue|the fix|then)\b|\b(first|second|third|fourth|fifth"
    r"|sixth|seventh|eighth) pass\b|\bbefore (issue|the fix|the change)\b|\bthe old\b", re.I)


def test_history_pattern_catches_narration_and_spares_present_tense() -> None:
    for text in ("the reading before issue 15's sixth pass", "unused since issue 11",
                 "was 0.2 s", "no longer used", "rows '0.2 s (before)'", "used to be 3"):
        assert HISTORY.search(text), text
    for text in ("brake command held before the start", "energy since the start (eq. 9)",
                 "time constant of the derivative low-pass", "events with an infeasible QP"):
        assert not HISTORY.search(text), text


@pytest.mark.parametrize("identifier", sorted(catalog()))
def test_published_descriptions_say_what_is(identifier: str) -> None:
    spec = catalog()[identifier]
    cls = spec.load()
    texts = {"<fmu>": spec.description} | {v.name: v.description for v in cls.variables}
    bad = {name: text for name, text in texts.items() if HISTORY.search(text or "")}
    assert not bad, bad


def test_fmu_reference_says_what_is() -> None:
    bad = [line for line in REFERENCE_PATH.read_text().splitlines() if HISTORY.search(line)]
    assert not bad, bad


def test_model_descriptions_publish_the_declarations(built_fmus) -> None:
    for identifier, spec in built_fmus.items():
        md = read_model_description(str(spec.path))
        published = {v.name: v for v in md.modelVariables}
        declared = spec.load().variables
        assert set(published) == {v.name for v in declared}, identifier
        for var in declared:
            got = published[var.name]
            assert (got.causality, got.type, got.description or "") == (
                var.causality, _TYPES[var.type], var.description), (identifier, var.name)
            if var.type is float:
                assert got.unit == var.unit, (identifier, var.name)
            for bound in ("min", "max"):
                want = getattr(var, bound)
                value = getattr(got, bound)
                assert (None if value is None else float(value)) == (
                    None if want is None or var.type is str else float(want)), (
                    identifier, var.name, bound)


def _default_params(cls) -> object:
    """What the core's declared defaults stand for, written independently of the FMU."""
    from controllers.hybrid.hybrid_mpc import HybridMpcParams
    from controllers.pid.speed_pid import DistributedSpeedPidParams
    from plants.emu import DEFAULT_CONFIGURATION, emu_config
    from plants.freight import FreightParams

    core, units = cls.core_class, cls.core_options.get("units")
    if core.params_class is not None:
        return core.params_class()
    return {"Emu": lambda: emu_config(DEFAULT_CONFIGURATION[units]),
            "FreightTrain": FreightParams,
            "DistributedSpeedPid": lambda: DistributedSpeedPidParams(units=units),
            "HybridMpc": HybridMpcParams,
            "MoveBlockingMpc": lambda: HybridMpcParams(move_blocks="3:4:3"),
            "ExplicitMpc": lambda: core.default_params,
            }[core.__name__]()


@pytest.mark.parametrize("identifier", sorted(catalog()))
def test_declared_starts_build_the_default_core(identifier: str) -> None:
    """The core built from the declared starts has the declared defaults; a changed value
    reaches the core's parameters under its declared name (declarations and build inverse)."""
    cls = catalog()[identifier].load()
    starts = {v.name: v.start for v in cls.variables if v.causality == "parameter"}
    core = cls.core_class.from_parameters(starts, data_dir=ROOT, **cls.core_options)
    assert core.p == _default_params(cls)
    fixed = getattr(cls.core_class, "fixed_by_data", ())  # EMPC: design of its region data
    name = next(n for n, v in starts.items() if isinstance(v, float) and v > 0
                and n not in ("v0", "s0", *fixed))
    changed = cls.core_class.from_parameters({**starts, name: starts[name] * 2},
                                             data_dir=ROOT, **cls.core_options)
    assert changed.p != core.p
    again = {v.name: v.start for v in parameters(changed.p)} if dataclasses.is_dataclass(
        changed.p) else {}
    if name in again:
        assert again[name] == starts[name] * 2


def test_groups_flatten_with_prefix_and_names_alias() -> None:
    @dataclasses.dataclass(frozen=True)
    class Inner:
        a: float = param(1.0, "m", "inner a", min=0.0)

    @dataclasses.dataclass(frozen=True)
    class Outer:
        horizon: int = param(10, description="horizon", min=2, name="N")
        inner: Inner = group(Inner(), "in_")
        k: float = param(5.0, "N/m", "stiffness", per_configuration=True)
        hidden: float = 3.0  # not declared: not an FMU variable

    declared = {v.name: v for v in parameters(Outer())}
    assert list(declared) == ["N", "in_a", "k"]
    assert declared["in_a"] == Var("in_a", "parameter", 1.0, "m", "inner a", 0.0, None)
    assert declared["k"].start == KEEP and "configuration value" in declared["k"].description
    built = build(Outer(k=7.0), {"N": 4, "in_a": 2.5, "k": KEEP})
    assert built == Outer(horizon=4, inner=Inner(2.5), k=7.0)  # KEEP keeps 7.0
    assert build(Outer(), {"k": 9.0}).k == 9.0
    with pytest.raises(ValueError, match="k = -3"):
        build(Outer(), {"k": -3.0})
    with pytest.raises(ValueError, match="unit 'furlong'"):
        param(1.0, "furlong")


def _var_calls(path: Path) -> list[int]:
    tree = ast.parse(path.read_text())
    return [node.lineno for node in ast.walk(tree) if isinstance(node, ast.Call)
            and getattr(node.func, "id", getattr(node.func, "attr", "")) in ("Var", "param")]


def test_wrappers_declare_nothing_themselves() -> None:
    """Names, units and defaults live on the cores: a ``*_fmu.py`` has no Var(...)/param(...)."""
    for spec in catalog().values():
        path = ROOT.joinpath(*spec.module.split(".")).with_suffix(".py")
        assert _var_calls(path) == [], f"{path}: declarations belong on the core"


def test_every_variable_name_is_declared_once_per_fmu() -> None:
    for identifier, spec in catalog().items():
        names = [v.name for v in spec.load().variables]
        assert len(names) == len(set(names)), identifier


def test_catalog_read_from_source_equals_the_imported_wrappers() -> None:
    """The catalog is read from the wrapper modules' source (no import: a run needs one or
    two of 24 wrappers); importing them all finds the same FMUs, classes and descriptions
    (a wrapper class not named ``...Fmu``, or a ``...Fmu`` class that is no slave, fails)."""
    from cosim.build.python import _imported_catalog

    assert catalog() == _imported_catalog()
    cut = {k: v.description for k, v in catalog().items() if not v.description.endswith(".")}
    assert not cut, f"descriptions cut mid-sentence: {cut}"


def _entry_texts() -> dict[str, str]:
    """What the paper pages publish from each reproduce entry: title, notes, run names,
    sources of the paper's figures and claims, figure titles, claim texts."""
    import tomllib

    from cosim.run.scenario import entry_files

    texts: dict[str, str] = {}
    for name, path in entry_files().items():
        data = tomllib.loads(path.read_text())
        texts[f"{name}: title"] = data.get("title", "")
        texts[f"{name}: notes"] = data.get("notes", "")
        for table in ("runs", "paper", "derived", "rankings", "figures", "claims", "metrics"):
            for i, row in enumerate(data.get(table, [])):
                for key in ("name", "source", "title", "paper", "label", "text"):
                    if isinstance(row.get(key), str):
                        texts[f"{name}: [[{table}]] #{i + 1} {key}"] = row[key]
    return texts


def test_entries_scenarios_and_metrics_say_what_is() -> None:
    """No history in what the paper pages, scenario descriptions and the metric list publish."""
    from cosim import papers
    from cosim.run.scenario import load_scenario, scenario_files

    texts = _entry_texts()
    for path in scenario_files().values():
        texts[f"{path.name}: description"] = load_scenario(path.stem).description
    for name, m in papers.registry().items():
        texts[f"metric {name}"] = m.description
        texts |= {f"metric {name}: {key}": text for key, (text, _) in m.outputs.items()}
    assert len(texts) > 100  # the walk found the entries and scenarios
    bad = {where: text for where, text in texts.items() if HISTORY.search(text or "")}
    assert not bad, bad
