"""Misspelt [summary] and [record] keys are errors (they used to be ignored silently)."""

from __future__ import annotations

import re

import pytest

from cosim.run.scenario import SCENARIO_DIR, ScenarioError, load_scenario


@pytest.mark.parametrize("table,line,says", [
    ("[summary]", "stop_piont = 400.0", "[summary] stop_piont: unknown key (did you mean "
                                        "'stop_point'?)"),
    ("[record]", 'variable = ["plant.v"]', "[record] variable: unknown key (did you mean "
                                           "'variables'?)"),
])
def test_misspelt_keys_are_rejected(tmp_path, table, line, says):
    text = (SCENARIO_DIR / "seed000_stop_pid.toml").read_text()
    assert table in text
    path = tmp_path / "typo.toml"
    path.write_text(text.replace(f"{table}\n", f"{table}\n{line}\n", 1))
    with pytest.raises(ScenarioError) as err:
        load_scenario(path)
    assert str(err.value) == f"{path}: {says}"


def test_every_shipped_scenario_uses_known_keys():
    for path in sorted(SCENARIO_DIR.glob("*.toml")):
        load_scenario(path)


def test_the_known_keys_are_those_the_metrics_read():
    """SUMMARY_KEYS lists exactly the [summary] keys cosim.run.metrics and the paper metrics
    (cosim/papers) read (``cfg.get("k")`` / ``cfg["k"]``), so a new metric cannot be rejected
    as a misspelling, nor a dead key accepted."""
    import ast
    from pathlib import Path

    from cosim import papers
    from cosim.run import metrics
    from cosim.run.scenario import SUMMARY_KEYS

    sources = [Path(metrics.__file__), *sorted(Path(papers.__file__).parent.glob("*.py"))]
    nodes = [n for f in sources for n in ast.walk(ast.parse(f.read_text()))]
    read = set()
    for node in nodes:
        if (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
                and node.func.attr == "get" and getattr(node.func.value, "id", "") == "cfg"
                and node.args and isinstance(node.args[0], ast.Constant)):
            read.add(node.args[0].value)
        if (isinstance(node, ast.Subscript) and getattr(node.value, "id", "") == "cfg"
                and isinstance(node.slice, ast.Constant)):
            read.add(node.slice.value)
    plotted = {"speed_limit"}  # drawn by cosim.run.results (the speed panel), not a metric
    assert read | plotted == set(SUMMARY_KEYS)


@pytest.mark.parametrize("line,says", [
    ("stoptime = 60", "[simulation] stoptime: unknown key (did you mean 'stop_time'?)"),
    ("output_intervall = 1.0", "[simulation] output_intervall: unknown key (did you mean "
                               "'output_interval'?)"),
])
def test_a_misspelt_simulation_key_is_named_before_a_missing_one(tmp_path, line, says):
    """`stoptime = 60` in place of stop_time: the unknown key is what the user must see."""
    text = (SCENARIO_DIR / "seed000_stop_pid.toml").read_text()
    text = re.sub(r"^stop_time = .*$", line, text, count=1, flags=re.M)
    assert line in text
    path = tmp_path / "typo.toml"
    path.write_text(text)
    with pytest.raises(ScenarioError) as err:
        load_scenario(path)
    assert str(err.value) == f"{path}: {says}"


def test_misspelt_fmu_and_top_level_keys_get_a_hint(tmp_path):
    text = (SCENARIO_DIR / "seed000_stop_pid.toml").read_text()
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
    text = (load_scenario("seed000_stop_pid").path.read_text()
            .replace('stop_point = "controller.stop_point"', 'stop_point = "controller.nope"'))
    bad = tmp_path / "bad.toml"
    bad.write_text(text)
    with pytest.raises(ScenarioError, match=r"bad.toml: \[summary\] stop_point = "
                                            r"'controller.nope'.*'controller' sets no 'nope'"):
        load_scenario(bad)
