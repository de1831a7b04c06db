"""results.csv keeps every float bit for bit (pandas writes repr, the shortest round-trip
text), and a folder being written by one run is refused to a second run at the same time."""

from __future__ import annotations

import json
from types import SimpleNamespace

import numpy as np
import pandas as pd

from cosim.run.results import write_results


def test_results_csv_round_trips_every_float(tmp_path):
    rng = np.random.default_rng(7)
    values = np.concatenate([rng.normal(size=50) * 10.0 ** rng.integers(-12, 12, size=50),
                             [1.0 / 3.0, 1.0 + 5e-10, 2.0**-1074, 1e300, -0.0]])
    frame = pd.DataFrame({"time": np.arange(values.size) * 0.1, "plant.v": values})
    result = SimpleNamespace(frame=frame, summary={"completed": True})
    write_results(result, tmp_path, plot=False)
    back = pd.read_csv(tmp_path / "results.csv")
    assert back["plant.v"].to_numpy().tobytes() == values.tobytes()
    # no scenario, so no declarations: time in s, the other column without a unit
    assert json.loads((tmp_path / "results.units.json").read_text()) == {"time": "s",
                                                                          "plant.v": None}
    assert back["time"].to_numpy().tobytes() == frame["time"].to_numpy().tobytes()


def test_a_second_run_into_a_locked_folder_is_refused(tmp_path):
    import pytest

    from cosim.run.results import OutputError, locked_destination

    out = tmp_path / "runs" / "a"
    with locked_destination(out):
        with pytest.raises(OutputError, match=r"--out .*another cosim run is writing into"):
            with locked_destination(out):
                pass
    with locked_destination(out):  # released at the end of the first
        pass


def test_cosim_run_refuses_a_folder_another_run_holds(built_fmus, tmp_path):
    import subprocess
    import sys

    from cosim.run.results import locked_destination

    with locked_destination(tmp_path):
        done = subprocess.run([sys.executable, "-m", "cosim.cli", "run", "seed000_stop_pid",
                               "--out", str(tmp_path), "--no-plot"],
                              capture_output=True, text=True, timeout=300)
    assert done.returncode == 2, done.stderr
    assert "another cosim run is writing into this folder" in done.stderr.replace("\n", " ")
    assert not (tmp_path / "results.csv").exists()
