"""A paper is a folder (issue 37): ``papers/NAME/`` holds its entry, scenarios, metric plug-ins,
scripts and tests; :func:`cosim.run.scenario.scenario_files` and :func:`entry_files` are the one
list of each, and the metric registry loads ``papers/*/metrics.py`` by path."""

from __future__ import annotations

from pathlib import Path

import pytest

from cosim import papers
from cosim.reproduce.entry import entry_aliases, entry_names, load_entry
from cosim.run import scenario as scenario_mod
from cosim.run.scenario import ScenarioError, entry_files, find_scenario, scenario_files

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib  # type: ignore[no-redef]

ROOT = Path(__file__).resolve().parents[1]


def test_every_paper_folder_has_its_entry_scenarios_and_readme() -> None:
    folders = sorted(p for p in (ROOT / "papers").iterdir() if p.is_dir())
    assert [p.name for p in folders] == entry_names() == [f"seed00{n}" for n in range(5)]
    for folder in folders:
        assert (folder / "entry.toml").is_file() and (folder / "README.md").is_file()
        shipped = sorted((folder / "scenarios").glob("*.toml"))
        assert shipped and all(p.stem.startswith(folder.name + "_") for p in shipped)
        assert f"docs/papers/{folder.name}.md" in (folder / "README.md").read_text()


def test_a_papers_tests_are_in_its_folder_and_in_the_suite() -> None:
    """A paper's own tests live in ``papers/NAME/tests/`` (issue 37), files named ``test_*.py``
    (a name no other folder of the suite uses: the import mode puts each test's folder on
    ``sys.path`` and imports it by its name), collected by ``python -m pytest`` (``papers`` in
    ``testpaths``) and named in the paper's README."""
    options = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["pytest"]
    assert options["ini_options"]["testpaths"] == ["tests", "papers"]
    with_tests = sorted(p.parent.name for p in (ROOT / "papers").glob("*/tests") if p.is_dir())
    assert with_tests == [f"seed00{n}" for n in range(1, 5)]
    for name in with_tests:
        folder = ROOT / "papers" / name
        files = sorted((folder / "tests").glob("*.py"))
        assert files and all(p.name.startswith("test_") for p in files), files
        assert f"python -m pytest papers/{name}/tests" in (folder / "README.md").read_text()
    names = [p.name for p in [*ROOT.joinpath("tests").rglob("test_*.py"),
                              *ROOT.joinpath("papers").glob("*/tests/**/test_*.py")]]
    assert len(names) == len(set(names)), sorted(n for n in set(names) if names.count(n) > 1)


def test_names_and_aliases_find_the_moved_files() -> None:
    assert find_scenario("seed000_stop_pid") == (
        ROOT / "papers" / "seed000" / "scenarios" / "seed000_stop_pid.toml")
    assert find_scenario("seed000_stop_pid.toml") == find_scenario("seed000_stop_pid")
    assert "seed004_crh3_empc" in scenario_files()
    assert entry_aliases()["liu2022"] == "seed000"
    entry = load_entry("liu2022")
    assert entry.name == "seed000" and entry.path == ROOT / "papers" / "seed000" / "entry.toml"
    # every run's and sweep's scenario resolves
    for name in entry_names():
        entry = load_entry(name)
        for run in entry.runs:
            find_scenario(run.scenario)
        for sweep in entry.sweeps:
            for s in sweep.scenarios:
                find_scenario(s)


def test_a_scenario_name_shipped_twice_names_both_files(tmp_path: Path,
                                                        monkeypatch: pytest.MonkeyPatch) -> None:
    (tmp_path / "scenarios").mkdir()
    (tmp_path / "papers" / "p1" / "scenarios").mkdir(parents=True)
    (tmp_path / "scenarios" / "twin.toml").write_text("")
    (tmp_path / "papers" / "p1" / "scenarios" / "twin.toml").write_text("")
    (tmp_path / "papers" / "p1" / "entry.toml").write_text("")
    monkeypatch.setattr(scenario_mod, "SCENARIO_DIR", tmp_path / "scenarios")
    monkeypatch.setattr(scenario_mod, "PAPERS_DIR", tmp_path / "papers")
    with pytest.raises(ScenarioError, match="twin") as err:
        scenario_files()
    assert str(tmp_path / "scenarios" / "twin.toml") in str(err.value)
    assert str(tmp_path / "papers" / "p1" / "scenarios" / "twin.toml") in str(err.value)
    assert entry_files() == {"p1": tmp_path / "papers" / "p1" / "entry.toml"}


def test_the_registry_loads_each_papers_metrics_by_path() -> None:
    modules = {m.module for m in papers.registry().values()}
    assert modules == {f"papers.seed00{n}.metrics" for n in range(1, 5)}
    assert papers.paper_metrics("seed001").unit_indices_metric is papers.lookup(
        "unit_indices").function  # loaded once: the module the registry holds
    assert "(`papers/seed001/metrics.py`;" in papers.reference_markdown()
    with pytest.raises(KeyError, match="seed000"):
        papers.paper_metrics("seed000")  # seed 000 has no metrics of its own
