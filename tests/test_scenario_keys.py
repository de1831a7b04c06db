"""Misspelt [summary] and [record] keys are errors (they used to be ignored silently)."""

from __future__ import annotations

import re

import pytest

from cosim.run.scenario import (
    ScenarioError,
    find_scenario,
    load_scenario,
    scenario_files,
)


@pytest.mark.parametrize("table,line,says", [
    ("[summary]", "stop_piont = 400.0", "[summary] stop_piont: unknown key (did you mean "
                                        "'stop_point'?)"),
    ("[record]", 'variable = ["plant.v"]', "[record] variable: unknown key (did you mean "
                                           "'variables'?)"),
])
def test_misspelt_keys_are_rejected(tmp_path, table, line, says):
    text = (find_scenario("seed000_stop_pid")).read_text()
    assert table in text
    path = tmp_path / "typo.toml"
    path.write_text(text.replace(f"{table}\n", f"{table}\n{line}\n", 1))
    with pytest.raises(ScenarioError) as err:
        load_scenario(path)
    assert str(err.value) == f"{path}: {says}"


def test_every_shipped_scenario_uses_known_keys():
    for path in list(scenario_files().values()):
        load_scenario(path)


def test_the_known_keys_are_those_the_metrics_read():
    """SUMMARY_KEYS lists exactly the [summary] keys cosim.run.metrics reads (``cfg.get("k")`` /
    ``cfg["k"]``), so a new metric cannot be rejected as a misspelling, nor a dead key accepted."""
    import ast
    from pathlib import Path

    from cosim.run import metrics
    from cosim.run.scenario import SUMMARY_KEYS

    tree = ast.parse(Path(metrics.__file__).read_text())
    read = set()
    for node in ast.walk(tree):
        if (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
                and node.func.attr == "get" and getattr(node.func.value, "id", "") == "cfg"
                and node.args and isinstance(node.args[0], ast.Constant)):
            read.add(node.args[0].value)
        if (isinstance(node, ast.Subscript) and getattr(node.value, "id", "") == "cfg"
                and isinstance(node.slice, ast.Constant)):
            read.add(node.slice.value)
    plotted = {"speed_limit"}  # drawn by cosim.run.figures.run (the speed panel), not a metric
    assert read | plotted == set(SUMMARY_KEYS)


def test_each_paper_metric_declares_the_keys_it_reads():
    """A registered metric reads (``run.series("k")`` / ``run.columns("k")`` /
    ``run.summary.get("k")`` / ``cfg["k"]`` / ``"k" in cfg``) only the keys its module's
    metrics declare or generic ones."""
    import ast
    import inspect

    from cosim import papers
    from cosim.run.scenario import SUMMARY_KEYS

    for name, m in papers.registry().items():
        module = inspect.getmodule(m.function)
        tree = ast.parse(inspect.getsource(module))
        def is_summary(node) -> bool:  # run.summary, or a name bound to it (cfg, summary)
            return ((isinstance(node, ast.Attribute) and node.attr == "summary")
                    or (isinstance(node, ast.Name) and node.id in ("cfg", "summary")))

        read = set()
        for node in ast.walk(tree):
            if (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
                    and node.args and isinstance(node.args[0], ast.Constant)
                    and isinstance(node.args[0].value, str)
                    and (node.func.attr in ("series", "columns")
                         or (node.func.attr == "get" and is_summary(node.func.value)))):
                read.add(node.args[0].value)
            if (isinstance(node, ast.Compare) and isinstance(node.left, ast.Constant)
                    and isinstance(node.left.value, str) and is_summary(node.comparators[0])):
                read.add(node.left.value)  # "final_stop_window" in cfg
            if (isinstance(node, ast.Subscript) and is_summary(node.value)
                    and isinstance(node.slice, ast.Constant)):
                read.add(node.slice.value)  # cfg["stop_point"]
        declared = {k for other in papers.registry().values()
                    if other.module == m.module for k in other.keys}
        assert read - set(SUMMARY_KEYS) <= declared, name


def test_paper_metrics_declare_their_entries_and_the_docs_list_them():
    """Every registered metric declares what it measures and each summary.json entry it adds
    (description, unit); the generated list in docs/scenarios.md names each entry with its
    unit; an entry a metric returns without declaring it is an error naming the metric."""
    from dataclasses import replace

    from cosim import papers

    text = papers.reference_markdown()
    for name, m in papers.registry().items():
        assert m.description and m.outputs, name
        assert f"**`{name}`**" in text
        for key, (meaning, unit) in m.outputs.items():
            assert meaning and unit, (name, key)
            assert f"| `{key}` | {meaning} | {unit} |" in text
    known = papers.lookup("distance_short")
    stub = replace(known, function=lambda run: {"distance_short_m": 1.0, "undeclared_m": 2.0})
    papers._REGISTRY["distance_short"] = stub
    try:
        with pytest.raises(ValueError, match=r"'distance_short'.*\['undeclared_m'\]"):
            papers.compute(["distance_short"], papers.RunRecord(frame=None, summary={}))
    finally:
        papers._REGISTRY["distance_short"] = known
    with pytest.raises(ValueError, match="output 'x_m'"):
        papers.metric("bad", description="d", outputs={"x_m": ("x", "")})


@pytest.mark.parametrize("line,says", [
    ('metrics = ["ctcs4"]', "[summary] metrics: no metric 'ctcs4' (did you mean 'ctcs3'?)"),
    ("ctcs3 = true", "[summary] ctcs3: a paper metric; name it in [summary] metrics = "
                     "['ctcs3', ...]"),
    ('unit_speeds = "plant.v"', "[summary] unit_speeds: read by the metric 'unit_indices', "
                                "which [summary] metrics does not name"),
])
def test_paper_metrics_are_named_before_their_keys_are_read(tmp_path, line, says):
    text = (find_scenario("seed000_stop_pid")).read_text()
    path = tmp_path / "metrics.toml"
    path.write_text(text.replace("[summary]\n", f"[summary]\n{line}\n", 1))
    with pytest.raises(ScenarioError) as err:
        load_scenario(path)
    assert str(err.value) == f"{path}: {says}"


def test_the_generic_runner_names_no_paper():
    """cosim/run holds no paper's name or rule: paper metrics live in cosim/papers."""
    from pathlib import Path

    import cosim.run

    pattern = re.compile(r"seed ?-?0\d\d|ctcs|seeds 0\d\d", re.IGNORECASE)
    found = [f"{p}:{i}" for p in sorted(Path(cosim.run.__file__).parent.rglob("*.py"))
             for i, line in enumerate(p.read_text().splitlines(), 1) if pattern.search(line)]
    assert found == []


@pytest.mark.parametrize("line,says", [
    ("stoptime = 60", "[simulation] stoptime: unknown key (did you mean 'stop_time'?)"),
    ("output_intervall = 1.0", "[simulation] output_intervall: unknown key (did you mean "
                               "'output_interval'?)"),
])
def test_a_misspelt_simulation_key_is_named_before_a_missing_one(tmp_path, line, says):
    """`stoptime = 60` in place of stop_time: the unknown key is what the user must see."""
    text = (find_scenario("seed000_stop_pid")).read_text()
    text = re.sub(r"^stop_time = .*$", line, text, count=1, flags=re.M)
    assert line in text
    path = tmp_path / "typo.toml"
    path.write_text(text)
    with pytest.raises(ScenarioError) as err:
        load_scenario(path)
    assert str(err.value) == f"{path}: {says}"


def test_misspelt_fmu_and_top_level_keys_get_a_hint(tmp_path):
    text = (find_scenario("seed000_stop_pid")).read_text()
    for old, new, says in (("[fmus.plant]\n", "[fmus.plant]\nsample_tme = 0.1\n",
                            "[fmus.plant] sample_tme: unknown key (did you mean 'sample_time'?)"),
                           ("[connections]", "[conections]",
                            "top level conections: unknown key (did you mean 'connections'?)")):
        assert old in text
        path = tmp_path / "typo.toml"
        path.write_text(text.replace(old, new, 1))
        with pytest.raises(ScenarioError) as err:
            load_scenario(path)
        assert str(err.value) == f"{path}: {says}"


@pytest.mark.parametrize("lo,hi,says", [
    (1.0, None, "0.5: must be at least 1.0"),
    (None, 2.0, "3.0: must be at most 2.0"),
    (0.0, 2.0, "3.0 outside [0.0, 2.0]"),
])
def test_a_range_with_one_bound_is_said_in_words(lo, hi, says):
    from types import SimpleNamespace

    from cosim.run.fmi_types import check_value

    value = 0.5 if lo == 1.0 else 3.0
    variable = SimpleNamespace(type="Real", min=lo, max=hi, unit="m")
    assert check_value(variable, value) == f"= {says} (m)"
    assert "None" not in check_value(variable, value)


def test_summary_reads_a_parameter_by_reference(tmp_path):
    """``stop_point = "controller.stop_point"`` follows ``--set controller.stop_point=450``
    (no stale copy); a reference to a parameter the scenario does not set names file and key."""
    import pytest

    from cosim.run.scenario import ScenarioError, load_scenario

    sc = load_scenario("seed000_stop_pid", ["controller.stop_point=450"])
    assert sc.summary["stop_point"] == 450.0
    assert load_scenario("seed000_stop_pid").summary["stop_point"] == 400.0
    decel = load_scenario("seed000_stop_pid", ["controller.ref_decel=0.6"]).summary
    assert decel["reference_decel"] == 0.6  # the stopping curve the metrics use, the controller's
    text = (load_scenario("seed000_stop_pid").path.read_text()
            .replace('stop_point = "controller.stop_point"', 'stop_point = "controller.nope"'))
    bad = tmp_path / "bad.toml"
    bad.write_text(text)
    with pytest.raises(ScenarioError, match=r"bad.toml: \[summary\] stop_point = "
                                            r"'controller.nope'.*'controller' sets no 'nope'"):
        load_scenario(bad)


def test_the_listing_follows_files_added_removed_and_new_paper_folders(tmp_path, monkeypatch):
    """scenario_files is read again when a file appears in or leaves one of its folders, or a
    paper gains a scenarios folder (it is cached between such changes, not between calls)."""
    import cosim.run.scenario as scenario

    shared, papers = tmp_path / "scenarios", tmp_path / "papers"
    shared.mkdir()
    (papers / "p1" / "scenarios").mkdir(parents=True)
    (papers / "p2").mkdir()
    monkeypatch.setattr(scenario, "SCENARIO_DIR", shared)
    monkeypatch.setattr(scenario, "PAPERS_DIR", papers)
    (shared / "a.toml").write_text("")
    (papers / "p1" / "scenarios" / "b.toml").write_text("")
    assert list(scenario_files()) == ["a", "b"]
    assert list(scenario_files()) == ["a", "b"]
    (shared / "a.toml").rename(shared / "c.toml")
    assert list(scenario_files()) == ["b", "c"]
    (papers / "p2" / "scenarios").mkdir()
    (papers / "p2" / "scenarios" / "d.toml").write_text("")
    assert scenario_files() == {"b": papers / "p1" / "scenarios" / "b.toml",
                                "c": shared / "c.toml", "d": papers / "p2" / "scenarios" / "d.toml"}
    (papers / "p2" / "scenarios" / "b.toml").write_text("")
    with pytest.raises(ScenarioError, match="scenario 'b' is shipped twice"):
        scenario_files()
