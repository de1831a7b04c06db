"""A rebuild within one process runs the new code (the FMU's entry module is named after a
digest of its bundle; it used to keep the first build's module from Python's cache)."""

from __future__ import annotations

import shutil
from pathlib import Path

from cosim.build import python as build
from cosim.run.scenario import find_scenario
from cosim.run.simulate import run_scenario

TWEAK = '''

_atocosim_test_outputs = BrakeDelayTrain.outputs
BrakeDelayTrain.outputs = lambda self: {**_atocosim_test_outputs(self),
                                        "s": _atocosim_test_outputs(self)["s"] + 1000.0}
'''


def test_a_rebuild_in_the_same_process_runs_the_new_code(built_fmus, tmp_path, monkeypatch):
    spec = built_fmus["BrakeDelayTrain"]
    dest = tmp_path / "fmus"
    fmu = build.build_fmu(spec, dest=dest)
    text = (find_scenario("seed000_stop_pid")).read_text()
    scenario = tmp_path / "local_plant.toml"
    scenario.write_text(text.replace('fmu = "BrakeDelayTrain"', f'fmu = "{fmu}"'))
    overrides = {"simulation.stop_time": 2.0}
    before = run_scenario(scenario, overrides=overrides, build=False, plot=False)
    assert before.frame["plant.s"].iloc[0] == 0.0

    copy = shutil.copy2

    def tweaked_copy(src, dst, *args, **kwargs):  # the same source tree, one changed file
        out = copy(src, dst, *args, **kwargs)
        if Path(src).name == "brake_delay.py" and Path(src).parent.name == "plants":
            with open(dst, "a") as f:
                f.write(TWEAK)
        return out

    monkeypatch.setattr(build.shutil, "copy2", tweaked_copy)
    assert build.build_fmu(spec, dest=dest) == fmu  # rebuilt in place
    monkeypatch.undo()
    after = run_scenario(scenario, overrides=overrides, build=False, plot=False)
    assert after.frame["plant.s"].iloc[0] == 1000.0  # the new code ran
