"""Messages a person reads: table names survive rich (no markup swallowed), errors caused by a
--set value name the --set option, a non-TTY run prints a progress line every ~10 %."""

from __future__ import annotations

import re
import subprocess
import sys

from cosim.run.scenario import SCENARIO_DIR


def cosim(*args: str, cwd=None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "cosim.cli", *args], capture_output=True,
                          text=True, timeout=600, cwd=cwd)


def one_line(done: subprocess.CompletedProcess) -> str:
    return done.stderr.replace("\n", " ")


def test_set_errors_name_the_set_option_and_keep_the_table_name(built_fmus, tmp_path):
    done = cosim("run", "seed000_stop_pid", "--set", "plant.mas=1", "--out", str(tmp_path))
    assert done.returncode == 2
    message = one_line(done)
    assert message.startswith("cosim run seed000_stop_pid error: --set plant.mas=1: ")
    assert "did you mean 'mass'?" in message
    assert "[fmus.plant.parameters] mas in " in message  # not eaten as rich markup


def test_unconnected_input_hint_keeps_its_table_names(built_fmus, tmp_path):
    text = (SCENARIO_DIR / "seed000_stop_pid.toml").read_text()
    text = re.sub(r'^"controller\.v" = "plant\.v"\n', "", text, flags=re.M)
    path = tmp_path / "unconnected.toml"
    path.write_text(text)
    done = cosim("run", str(path), "--out", str(tmp_path / "out"))
    assert done.returncode == 2
    message = one_line(done)
    assert "to [connections] or a constant in [fmus.controller.inputs]" in message, message


def test_help_keeps_bracketed_table_names():
    done = cosim("run", "--help")
    assert "[simulation] algorithm" in done.stdout


def test_non_tty_run_prints_progress_every_tenth_and_set_takes_effect(built_fmus, tmp_path):
    done = cosim("run", "seed000_stop_pid", "--set", "plant.v0=15", "--no-plot",
                 "--out", str(tmp_path))
    assert done.returncode == 0, done.stderr
    lines = [line for line in done.stderr.splitlines() if " s sim (" in line]
    percents = [int(re.search(r"\((\d+) %\)", line)[1]) for line in lines]
    assert percents == list(range(10, 101, 10)), done.stderr
    assert all("real-time factor" in line for line in lines)
    import pandas as pd

    frame = pd.read_csv(tmp_path / "results.csv")
    assert frame["plant.v"].iloc[0] == 15.0  # the value the FMU received, not the file's 20


def test_sweep_help_keeps_the_bracketed_extra():
    done = cosim("sweep", "--help")
    assert "ato-cosim[dask]" in done.stdout.replace("\n", " ").replace("│", "").replace(" ", "")
