"""What an FMU says reaches the user: the Python exception's message through the FMI log, every
FMI call (not only doStep) named with the instance and the time, partial results kept."""

from __future__ import annotations

import pytest
from fmpy import read_model_description

from cosim.run.master import FmuCallError, Master
from cosim.run.scenario import ScenarioError, load_scenario
from cosim.run.simulate import run_scenario


def test_integer_parameters_declare_their_range(built_fmus):
    md = read_model_description(str(built_fmus["StopRmpc"].path))
    n = next(v for v in md.modelVariables if v.name == "N")
    assert n.type == "Integer" and (int(n.min), int(n.max)) == (2, 60)


def test_out_of_range_integer_is_caught_before_anything_runs(built_fmus, tmp_path):
    with pytest.raises(ScenarioError, match=r"controller\.N = 1000 outside \[2, 60\]"):
        run_scenario("seed000_stop_rmpc", overrides={"controller.N": 1000}, build=False,
                     out_dir=tmp_path / "out")
    assert not (tmp_path / "out").exists()


def test_a_failing_call_outside_dostep_names_fmu_time_and_reason(built_fmus):
    """A setReal the FMU rejects at the first progress report from t = 5 s on (a fixed
    parameter): the FMU's own message, the instance, the call and the time; what was recorded
    up to then is kept."""
    sc = load_scenario("seed000_stop_pid")
    master: Master
    at: list[float] = []

    def meddle(t: float, _total: float) -> None:
        if t >= 5.0:
            at.append(t)
            master.by_name["plant"].set("mass", 1.0)

    master = Master(sc, progress=meddle)
    with pytest.raises(FmuCallError) as err:
        master.run()
    message = str(err.value)
    assert message.startswith(f"plant: setReal at t = {at[0]:g} s failed: ")
    assert "mass" in message and "fixed after initialisation" in message
    assert "PyObject_CallMethod" not in message and "unknown error" not in message
    assert err.value.status is not None and err.value.status >= 3  # fmi2Error or fmi2Fatal
    partial = master.partial
    assert partial is not None and not partial.completed
    # the last output point before the failing call (a report comes after the step to its
    # point, before the point's values are recorded)
    assert partial.frame["time"].iloc[-1] == pytest.approx(at[0] - sc.simulation.output_interval)
    assert partial.error.startswith(f"FmuCallError: plant: setReal at t = {at[0]:g} s")
