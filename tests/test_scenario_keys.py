"""Misspelt [summary] and [record] keys are errors (they used to be ignored silently)."""

from __future__ import annotations

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
    plotted = {"speed_limit"}  # drawn by cosim.run.results (the speed panel), not a metric
    assert read | plotted == set(SUMMARY_KEYS)


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
