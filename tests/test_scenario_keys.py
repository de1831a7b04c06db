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
