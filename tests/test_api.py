"""The Python entry point (:mod:`cosim.api`): the same run as the CLI's, overrides with the
``--set`` semantics, units as the FMUs declare them, runs compared side by side."""

from __future__ import annotations

import dataclasses
import json
import math
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest
from fmpy import read_model_description

from cosim import api
from cosim.run.scenario import ScenarioError

SHORT = {"simulation.stop_time": 20.0}  # seed000_stop_pid's first 20 s: the train still runs


@pytest.fixture(scope="module")
def short_run() -> api.Run:
    return api.run("seed000_stop_pid", SHORT, plot=False)


def test_a_run_equals_the_cli_run_of_the_same_scenario(short_run: api.Run,
                                                       tmp_path: Path) -> None:
    done = subprocess.run(
        [sys.executable, "-m", "cosim.cli", "run", "seed000_stop_pid", "--quiet", "--no-plot",
         "--set", "simulation.stop_time=20", "--out", str(tmp_path)],
        capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    cli = pd.read_csv(tmp_path / "results.csv")  # written with repr: round-trip exact
    pd.testing.assert_frame_equal(short_run.frame, cli, check_exact=True)
    summary = json.loads((tmp_path / "summary.json").read_text())
    for key in ("stop_error_m", "speed_rmse_mps", "command_switches", "executions"):
        assert short_run.summary[key] == summary[key], key


def test_overrides_take_set_texts_or_python_values() -> None:
    by_text = api.load("seed000_stop_pid", ["plant.mass=539000", "controller.sample_time=0.4"])
    by_value = api.load("seed000_stop_pid", {"plant.mass": 539000,
                                             "controller.sample_time": 0.4})
    for sc in (by_text, by_value):
        assert sc.components["plant"].parameters["mass"] == 539000
        assert sc.components["controller"].sample_time == 0.4
    with pytest.raises(ScenarioError, match=r"--set plant\.mas=1: .*did you mean 'mass'"):
        api.run("seed000_stop_pid", ["plant.mas=1"], plot=False)
    with pytest.raises(ScenarioError, match="no FMU named 'plnt'"):
        api.load("seed000_stop_pid", {"plnt.mass": 1.0})
    with pytest.raises(ValueError, match="a loaded scenario has its own"):
        api.run(by_value, SHORT)
    assert "seed000_stop_pid" in api.scenarios()


def test_units_are_the_fmus_declared_units(short_run: api.Run) -> None:
    declared = {}
    for name, component in short_run.scenario.components.items():
        md = read_model_description(str(component.fmu_path), validate=False)
        for v in md.modelVariables:  # the unit on the variable or on its declared type
            unit = v.unit or (v.declaredType.unit if v.declaredType is not None else None)
            declared[f"{name}.{v.name}"] = unit
    units = short_run.units
    assert list(units) == list(short_run.frame.columns) and units["time"] == "s"
    assert units["plant.v"] == "m/s" and units["plant.s"] == "m"
    for column, unit in units.items():
        if column != "time":
            assert unit == declared[column], column
    labelled = short_run.with_units()
    assert list(labelled.columns) == [(c, units[c] or "") for c in short_run.frame.columns]
    assert (labelled.to_numpy() == short_run.frame.to_numpy()).all()
    assert short_run.frame.attrs["units"] == units
    assert short_run.variables.loc["plant.v", "description"]


def test_compare_puts_each_runs_metrics_in_its_column(short_run: api.Run) -> None:
    shorter = api.run("seed000_stop_pid", {"simulation.stop_time": 10.0}, plot=False)
    table = api.compare({"20 s": short_run, "10 s": shorter})
    assert list(table.columns) == ["20 s", "10 s"]
    for label, one in (("20 s", short_run), ("10 s", shorter)):
        assert table.loc["stop_error_m", label] == one.summary["stop_error_m"]
        for fmu, n in one.summary["executions"].items():
            assert table.loc[f"executions.{fmu}", label] == n
    assert table.loc["sim_time_s"].tolist() == [20.0, 10.0]
    by_list = api.compare([short_run, short_run], metrics=["stop_error_m", "no_such_metric"])
    assert list(by_list.columns) == ["seed000_stop_pid", "seed000_stop_pid (1)"]
    assert list(by_list.index) == ["stop_error_m"]
    assert list(api.compare({"a": short_run}, metrics=["stop_error_m", "energy_kwh"]).index
                ) == ["stop_error_m"]  # a metric no run has: no row
    lacking = api.Run(dataclasses.replace(short_run.result, summary={"sim_time_s": 1.0}))
    table = api.compare({"full": short_run, "lacking": lacking})
    assert math.isnan(table.loc["stop_error_m", "lacking"])
    assert table.loc["sim_time_s", "lacking"] == 1.0


def test_figure_is_the_run_figure_and_save_writes_the_run_files(short_run: api.Run,
                                                                tmp_path: Path) -> None:
    import matplotlib.pyplot as plt

    fig = short_run.figure()
    try:
        labels = [ax.get_xlabel() for ax in fig.axes]
        assert any("position" in label for label in labels), labels
    finally:
        plt.close(fig)
    written = short_run.save(tmp_path / "out")
    assert sorted(p.name for p in written) == ["plot.png", "results.csv", "results.units.json",
                                               "summary.json"]
    pd.testing.assert_frame_equal(pd.read_csv(tmp_path / "out" / "results.csv"),
                                  short_run.frame, check_exact=True)


def test_results_units_json_holds_each_columns_declared_unit(short_run: api.Run,
                                                              tmp_path: Path) -> None:
    """The sidecar beside results.csv: one entry per column, in the table's order, each the
    unit the FMU declares (as ``Run.units``); ``read_results`` gives the table bit for bit
    with those units in ``attrs``, and ``{}`` for a folder without the sidecar."""
    short_run.save(tmp_path, plot=False)
    units = json.loads((tmp_path / "results.units.json").read_text(encoding="utf-8"))
    assert list(units) == list(short_run.frame.columns)
    assert units == short_run.units
    assert units["time"] == "s" and units["plant.v"] == "m/s"
    back = api.read_results(tmp_path)
    pd.testing.assert_frame_equal(back, short_run.frame, check_exact=True)
    assert back.attrs["units"] == units
    (tmp_path / "results.units.json").unlink()
    assert api.read_results(tmp_path).attrs["units"] == {}


def test_a_plant_run_in_code_equals_fmpy_running_its_fmu(tmp_path: Path) -> None:
    """The plant-only scenario of docs/python.md and the fmpy snippet of docs/other_tools.md
    are the same simulation: equal positions and speeds at every output point (both step the
    FMU between the same output points; its sub-steps lie on its own absolute grid)."""
    import numpy as np
    from fmpy import simulate_fmu

    path = tmp_path / "braking.toml"
    path.write_text('[simulation]\nstop_time = 40.0\noutput_interval = 0.5\n'
                    '[fmus.train]\nfmu = "BrakeDelayTrain"\n'
                    '[fmus.train.parameters]\nv0 = 20.0\n'
                    '[fmus.train.inputs]\nbrake_command = 50.0\n')
    ours = api.run(path, plot=False)
    brake = np.array([(0.0, 50.0)], dtype=[("time", float), ("brake_command", float)])
    theirs = simulate_fmu(str(ours.scenario.components["train"].fmu_path),
                          start_values={"v0": 20.0}, input=brake, stop_time=40.0,
                          output_interval=0.5, output=["v", "s"])
    assert np.array_equal(ours.frame["time"].to_numpy(), theirs["time"])
    for name in ("v", "s"):
        # the same FMU code on the same inputs and step grid, in this one process: bit-equal
        assert np.array_equal(ours.frame[f"train.{name}"].to_numpy(), theirs[name]), name
    assert ours.frame["train.v"].iloc[-1] == 0.0  # it came to rest inside the run
