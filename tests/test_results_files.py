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
        with pytest.raises(OutputError, match=r"--out .*another cosim command is writing into"):
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
    assert "another cosim command is writing into this folder" in done.stderr.replace("\n", " ")
    assert not (tmp_path / "results.csv").exists()


HOLD = ("import sys\nfrom cosim.run.results import locked_destination\n"
        "with locked_destination(sys.argv[1], is_dir=sys.argv[2] == 'dir'):\n"
        "    print('held', flush=True)\n    sys.stdin.read()\n")


def _holder(destination, is_dir=True):
    """A second process holding the lock on ``destination`` until its stdin closes."""
    import subprocess
    import sys

    proc = subprocess.Popen([sys.executable, "-c", HOLD, str(destination),
                             "dir" if is_dir else "file"],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    assert proc.stdout.readline() == "held\n"
    return proc


def test_sweep_reproduce_and_export_refuse_a_destination_another_process_holds(tmp_path):
    """``cosim sweep``, ``reproduce`` and ``export`` (run in this process through typer's test
    runner) refuse a destination whose lock another process holds, naming its pid, and write
    nothing."""
    from tests.cli_inproc import cosim_inproc

    commands = {
        tmp_path / "sweep": ["sweep", "seed000_stop_pid", "--set", "controller.kp=1,2",
                             "--out", str(tmp_path / "sweep")],
        tmp_path / "reproduce": ["reproduce", "seed000", "--out", str(tmp_path / "reproduce")],
        tmp_path / "a.ssp": ["export", "seed000_stop_pid", "--ssp", str(tmp_path / "a.ssp")],
    }
    for destination, args in commands.items():
        is_dir = destination.suffix != ".ssp"
        holder = _holder(destination, is_dir)
        try:
            done = cosim_inproc(*args)
        finally:
            holder.communicate("")
        message = " ".join(done.stderr.split())
        assert done.exit_code == 2, done.stderr
        assert f"{destination}: another cosim command is writing into" in message
        assert f"pid {holder.pid}:" in message
        assert not (destination / "sweep.csv").exists() and not destination.is_file()


def test_a_lock_whose_holder_was_killed_is_taken_over(tmp_path):
    import os

    from cosim.run.results import LOCK_FILE, locked_destination

    holder = _holder(tmp_path)
    holder.kill()
    holder.wait()
    holder.stdin.close()
    holder.stdout.close()
    with locked_destination(tmp_path):
        assert (tmp_path / LOCK_FILE).read_text().split()[0] == str(os.getpid())
