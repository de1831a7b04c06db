"""A C program (gcc + fmpy's FMI 3 headers) runs our FMI 3 builds without Python in the host
and without LD_PRELOAD: the front loads the shim, the shim libpython. The plant's results equal
the FMI 2 build's under fmpy (same core); a controller in Event Mode announces every sample."""

from __future__ import annotations

import os
import site
import subprocess
from pathlib import Path

import numpy as np
import pytest
from fmpy import extract, read_model_description

from tests.c_host.test_c_host import COMMAND, N_STEPS, OUTPUTS, STEP, fmpy_reference


@pytest.fixture(scope="module")
def host3(c_hosts) -> Path:
    """fmu3_host.c compiled (the root conftest's ``c_hosts``)."""
    return c_hosts("fmu3_host")


def _run(host3: Path, path: Path, tmp: Path, step: float, n: int, event_mode: bool,
         inputs: dict[str, float], outputs: tuple[str, ...]) -> np.ndarray:
    md = read_model_description(str(path))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    unzipdir = extract(str(path), unzipdir=str(tmp))
    env = {k: v for k, v in os.environ.items() if k not in ("LD_PRELOAD", "PYTHONHOME")}
    env["PYTHONPATH"] = os.pathsep.join([*site.getsitepackages(),
                                         os.environ.get("PYTHONPATH", "")])
    args = [str(host3), unzipdir, md.coSimulation.modelIdentifier, md.guid, repr(step), str(n),
            str(int(event_mode)), *[f"in:{vr[k]}={v!r}" for k, v in inputs.items()],
            *[f"out:{vr[name]}" for name in outputs]]
    done = subprocess.run(args, capture_output=True, text=True, timeout=120, env=env)
    assert done.returncode == 0, done.stderr
    assert "freed" in done.stderr and "corrupted" not in done.stderr
    return np.array([[float(x) for x in line.split(",")] for line in done.stdout.split()])


def test_c_host_runs_the_fmi3_plant_like_the_fmi2_build(host3, built_fmus, built_fmus_fmi3,
                                                        tmp_path):
    path2 = built_fmus["BrakeDelayTrain"].path
    plant = (path2, read_model_description(str(path2)),
             extract(str(path2), unzipdir=str(tmp_path / "fmi2")))
    rows = _run(host3, built_fmus_fmi3["BrakeDelayTrain"].path_fmi3, tmp_path / "fmi3", STEP,
                N_STEPS, False, {"brake_command": COMMAND}, OUTPUTS)
    np.testing.assert_array_equal(rows[:, :-1], fmpy_reference(plant))  # %.17g round-trips
    assert np.isnan(rows[:, -1]).all()  # no Event Mode: no event time announced


def test_c_host_runs_an_fmi3_controller_in_event_mode(host3, built_fmus_fmi3, tmp_path):
    """StopPid samples every T: in Event Mode at each sample, nextEventTime = the next one."""
    path = built_fmus_fmi3["StopPid"].path_fmi3
    md = read_model_description(str(path))
    T = next(float(v.start) for v in md.modelVariables if v.name == "sample_time")
    rows = _run(host3, path, tmp_path, T, 10, True, {}, ("next_event_time",))
    t, output, announced = rows[:, 0], rows[:, 1], rows[:, 2]
    np.testing.assert_allclose(announced, t + T, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(output, announced)
