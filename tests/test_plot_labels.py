"""Plots a person reads: the command axis in a physical unit (kN, %, m/s²), never a variable
name and raw N; the stop error in cm under 1 m, otherwise in m."""

from __future__ import annotations

import pytest

from cosim.run.results import display_unit, format_stop_error, variable_unit
from cosim.run.scenario import load_scenario


@pytest.mark.parametrize("error,text", [(0.149, "+14.9 cm"), (-0.004, "-0.4 cm"),
                                        (3.4, "+3.40 m"), (-340.2, "-340.20 m")])
def test_stop_error_in_cm_under_a_metre_else_in_m(error, text):
    assert format_stop_error(error) == text


@pytest.mark.parametrize("scenario,command,shown", [
    ("seed000_stop_pid", "controller.brake_command", (1.0, "%")),
    ("seed004_crh3_pid", None, (1e-3, "kN")),
])
def test_command_axis_has_a_physical_unit(built_fmus, scenario, command, shown):
    sc = load_scenario(scenario)
    ref = command or sc.summary["command"]
    assert display_unit(variable_unit(sc, ref)) == shown
