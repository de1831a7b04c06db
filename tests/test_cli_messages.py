"""Messages a person reads: table names survive rich (no markup swallowed), errors caused by a
--set value name the --set option, a non-TTY run prints a progress line every ~10 %.

Messages the command prints before any run are read in this process through typer's test
runner (the text a process prints: test_no_help_text_is_cut_at_80_columns compares the two);
runs (their lines come from the forked run child) and sweeps that print tables run as
processes."""

from __future__ import annotations

import re
import shlex
import subprocess
import sys

import pytest
from typer.testing import Result

from cosim.run.scenario import find_scenario
from tests.cli_inproc import cosim_inproc, no_traceback


def cosim(*args: str, env=None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "cosim.cli", *args], capture_output=True,
                          text=True, timeout=600, env=env)


def one_line(done: subprocess.CompletedProcess | Result) -> str:
    return done.stderr.replace("\n", " ")


@pytest.fixture(scope="module")
def pid_run_at_v0_15(built_fmus, tmp_path_factory):
    """``cosim run seed000_stop_pid --set plant.v0=15 --no-plot`` as a process (the progress
    lines come from its run child): the finished process and its --out folder."""
    out = tmp_path_factory.mktemp("pid_run_at_v0_15")
    done = cosim("run", "seed000_stop_pid", "--set", "plant.v0=15", "--no-plot",
                 "--out", str(out))
    return done, out


def test_set_errors_name_the_set_option_and_keep_the_table_name(built_fmus, tmp_path):
    done = cosim_inproc("run", "seed000_stop_pid", "--set", "plant.mas=1", "--out", str(tmp_path))
    assert done.exit_code == 2
    message = one_line(done)
    # the command echoed whole (a log shows what ran), then the error
    echo = f"cosim run seed000_stop_pid --out {shlex.quote(str(tmp_path))} --set plant.mas=1"
    assert message.startswith(f"{echo} error: --set plant.mas=1: "), message
    assert "did you mean 'mass'?" in message
    assert "[fmus.plant.parameters] mas in " in message  # not eaten as rich markup


def test_unconnected_input_hint_keeps_its_table_names(built_fmus, tmp_path):
    """An input left unconnected keeps its start value, said in the log when the FMUs are
    loaded (a 5-s run, as a process: the line comes from its run child); with
    ``unconnected_inputs = "error"`` the run is refused, naming where to connect or set it."""
    text = (find_scenario("seed000_stop_pid")).read_text()
    text = re.sub(r'^"controller\.v" = "plant\.v"\n', "", text, flags=re.M)
    path = tmp_path / "unconnected.toml"  # kept at its start value, said in the log
    path.write_text(text)
    done = cosim("run", str(path), "--out", str(tmp_path / "out"), "--no-plot",
                 "--set", "simulation.stop_time=5")
    assert done.returncode == 0, done.stderr
    assert "keep their start values: controller.v" in done.stderr, done.stderr
    strict = tmp_path / "strict.toml"  # refused, naming where to connect or set it
    strict.write_text(text.replace("[simulation]\n",
                                   '[simulation]\nunconnected_inputs = "error"\n', 1))
    done = cosim_inproc("run", str(strict), "--out", str(tmp_path / "strict"))
    assert done.exit_code == 2
    message = one_line(done)
    assert "to [connections] or a constant in [fmus.controller.inputs]" in message, message


def test_help_keeps_bracketed_table_names():
    done = cosim_inproc("run", "--help")
    assert "[simulation] algorithm" in done.stdout


def test_non_tty_run_prints_progress_every_tenth_and_set_takes_effect(pid_run_at_v0_15):
    done, out = pid_run_at_v0_15
    assert done.returncode == 0, done.stderr
    lines = [line for line in done.stderr.splitlines() if " s sim (" in line]
    percents = [int(re.search(r"\((\d+) %\)", line)[1]) for line in lines]
    assert percents == list(range(10, 101, 10)), done.stderr
    assert all("real-time factor" in line for line in lines)
    import pandas as pd

    frame = pd.read_csv(out / "results.csv")
    assert frame["plant.v"].iloc[0] == 15.0  # the value the FMU received, not the file's 20


def test_sweep_help_keeps_the_bracketed_extra():
    done = cosim_inproc("sweep", "--help")
    assert "ato-cosim[dask]" in done.stdout.replace("\n", " ").replace("│", "").replace(" ", "")


def test_command_list_gives_each_command_one_line_at_80_columns():
    """``cosim --help`` at 80 columns: each command's help is one short sentence, on the
    command's own line of the panel (no continuation line)."""
    import typer

    from cosim.cli import app

    done = cosim_inproc("--help", env={"COLUMNS": "80"})
    lines = done.stdout.splitlines()
    start = next(i for i, line in enumerate(lines) if "Commands" in line)
    rows = lines[start + 1:next(i for i in range(start + 1, len(lines))
                                if lines[i].startswith("╰"))]
    names = list(typer.main.get_command(app).commands)
    assert [row.split()[1] for row in rows] == names, rows
    assert all(len(row) <= 80 and row.rstrip(" │").endswith(".") for row in rows), rows


def test_command_help_paragraphs_wrap_at_the_terminal_not_mid_sentence():
    """Every paragraph of every command's help is one line, so the terminal wraps it at its
    own width (typer's rich help keeps a docstring's line breaks, which split sentences at any
    width); the first paragraph is one short sentence."""
    import typer

    from cosim.cli import app, one_line_paragraphs

    assert one_line_paragraphs("A b.\n\n    c\n    d.\n") == "A b.\n\nc d."
    for name, cmd in typer.main.get_command(app).commands.items():
        first = cmd.help.split("\n\n")[0]
        assert "\n" not in cmd.help.replace("\n\n", ""), name
        assert first.endswith(".") and ". " not in first and len(first) <= 60, name


def _table_blocks(done: subprocess.CompletedProcess) -> tuple[list[str], list[int]]:
    """The output's lines (none wider than 80 columns) and the header line of each block of
    its table (at least two: the table is split)."""
    lines = done.stdout.splitlines()
    assert max(len(line) for line in lines) <= 80, done.stdout
    headers = [i for i, line in enumerate(lines) if line.startswith("scenario")]
    assert len(headers) >= 2, done.stdout  # split into blocks
    return lines, headers


def test_perturb_table_keeps_the_grid_column_in_every_block_and_one_notation(tmp_path):
    """``sweep --perturb`` at 80 columns: every block of the summary table repeats the grid
    value beside the scenario (rows that differ only in it stay apart), and each column has
    one notation (the masses as integers, the stop errors with the same decimals)."""
    done = cosim("sweep", "seed000_stop_pid", "--set", "plant.mass=440000,539000",
                 "--perturb", "plant.brake_time_constant=0.3..0.6", "--samples", "2",
                 "--workers", "1", "--no-plot", "--out", str(tmp_path / "sweep"))
    assert done.returncode == 0, done.stderr
    lines, headers = _table_blocks(done)
    for i in headers:
        assert lines[i].split()[:2] == ["scenario", "mass"], done.stdout
        assert [line.split()[1] for line in lines[i + 2:i + 4]] == ["440000", "539000"]
    assert "e+0" not in done.stdout and "e-0" not in done.stdout, done.stdout
    errors = [line.split()[3:6] for line in lines[headers[0] + 2:headers[0] + 4]]
    decimals = {len(x.partition(".")[2]) for row in errors for x in row}
    assert len(decimals) == 1, errors


def test_progress_and_summary_real_time_factors_say_what_they_measure(pid_run_at_v0_15):
    """The progress lines' real-time factor is the stepping's; the summary's is the whole
    run's (the FMUs' loading included) and names the stepping's, the last progress line's
    (whatever the run's plant.v0)."""
    import json

    done, out = pid_run_at_v0_15
    assert done.returncode == 0, done.stderr
    last = [line for line in done.stderr.splitlines() if "(100 %)" in line][-1]
    stepping = re.search(r"real-time factor of the stepping (\S+)$", last)[1]
    text = " ".join(done.stdout.replace("│", " ").split())
    whole = json.loads((out / "summary.json").read_text())["real_time_factor"]
    assert (f"real_time_factor {whole:.6g} (whole run: loading and initialising the FMUs "
            f"included; stepping alone {stepping}, as the progress lines)") in text, text


@pytest.mark.parametrize("item,message", [
    ("plant.mas=+-10%", "--perturb plant.mas: plant (BrakeDelayTrain) has no variable 'mas' "
                        "(did you mean 'mass'?)"),
    ("plnt.mass=+-10%", "--perturb plnt.mass: seed000_stop_pid has no FMU named 'plnt' "
                        "(did you mean 'plant'?)"),
])
def test_perturb_typos_get_did_you_mean(tmp_path, item, message):
    done = cosim_inproc("sweep", "seed000_stop_pid", "--set", "plant.mass=490000",
                        "--perturb", item, "--samples", "1", "--workers", "1", "--no-plot",
                        "--out", str(tmp_path / "s"))
    assert done.exit_code == 2
    assert message in one_line(done), done.stderr


def test_validate_typos_get_did_you_mean(tmp_path, monkeypatch):
    (tmp_path / "StopPid.fmu").write_bytes(b"")
    done = cosim_inproc("validate", str(tmp_path / "StopPdi.fmu"))
    assert done.exit_code == 2
    assert f"no such file (did you mean '{tmp_path / 'StopPid.fmu'}'?)" in one_line(done)
    (tmp_path / "empty").mkdir()  # no .fmu near: the closest identifier
    with monkeypatch.context() as in_empty:
        in_empty.chdir(tmp_path / "empty")
        done = cosim_inproc("validate", "StopPdi.fmu")
    assert "StopPdi.fmu: no such file (did you mean 'StopPid'?)" in one_line(done)
    done = cosim_inproc("validate", "--native", "StopMcp")
    assert done.exit_code == 2
    assert "no native model of 'StopMcp'; native: " in one_line(done)
    assert "(did you mean 'StopMpc'?)" in one_line(done)


def test_no_help_text_is_cut_at_80_columns():
    """Every command's ``--help`` at 80 columns shows each word whole (rich cuts a word wider
    than its column with an ellipsis). In this process, through typer's test runner: rich
    reads the width from ``COLUMNS`` as in a terminal of its own, and the text is the one a
    ``python -m cosim.cli`` process prints (the first command's is compared)."""
    import os

    import typer
    from typer.testing import CliRunner

    from cosim.cli import app

    runner = CliRunner()
    for i, name in enumerate(["", *typer.main.get_command(app).commands]):
        done = runner.invoke(app, [*name.split(), "--help"], env={"COLUMNS": "80"},
                             prog_name="python -m cosim.cli")
        assert done.exit_code == 0, done.output
        assert "…" not in done.output, (name, done.output)
        if i == 0:
            alone = cosim("--help", env={**os.environ, "COLUMNS": "80"})
            assert alone.stdout == done.output


def test_sweep_table_keeps_the_grid_columns_in_every_block(tmp_path):
    done = cosim("sweep", "seed000_stop_pid", "seed000_stop_pid_plain",
                 "--set", "plant.mass=440000,539000", "--set", "controller.ref_decel=0.5,0.55",
                 "--workers", "1", "--no-plot", "--out", str(tmp_path / "sweep"))
    assert done.returncode == 0, done.stderr
    lines, headers = _table_blocks(done)
    for i in headers:
        assert lines[i].split()[:3] == ["scenario", "mass", "ref_decel"], done.stdout
        assert [line.split()[1:3] for line in lines[i + 2:i + 4]] == [
            ["440000", "0.50"], ["440000", "0.55"]], done.stdout


@pytest.mark.parametrize("override,says", [
    ("simulation.stop_time=1e300", "stop_time = 1e+300: out of range: times are integer "
                                   "nanoseconds in 64 bits"),
    ("simulation.stop_time=1e10", "stop_time = 10000000000.0: out of range"),
    ("simulation.start_time=-1e10", "start_time = -10000000000.0: out of range"),
    ("simulation.stop_time=-1", "stop_time = -1.0: must be positive"),
    ("simulation.stop_time=nan", "stop_time = nan: must be finite"),
    ("simulation.output_interval=1e-12", "output_interval = 1e-12: below the master's 1 ns"),
    ("controller.sample_time=1e300", "sample_time = 1e+300: out of range"),
])
def test_out_of_range_times_name_the_option_key_and_value(override, says):
    from cosim.run.scenario import ScenarioError, load_scenario

    with pytest.raises(ScenarioError) as err:
        load_scenario("seed000_stop_pid", [override])
    assert str(err.value).startswith(f"--set {override}: {says}"), err.value
    assert "seed000_stop_pid.toml" in str(err.value)  # the file whose key it replaces


def test_huge_stop_time_and_latin1_scenario_are_errors_without_traceback(tmp_path):
    text = (find_scenario("seed000_stop_pid")).read_text()
    huge = tmp_path / "huge.toml"
    huge.write_text(re.sub(r"^stop_time = .*$", "stop_time = 1e300", text, count=1, flags=re.M))
    done = cosim_inproc("run", str(huge), "--out", str(tmp_path / "a"), "--quiet")
    assert done.exit_code == 2 and "Traceback" not in done.stderr and no_traceback(done)
    assert f"{huge}: [simulation] stop_time = 1e+300: out of range" in one_line(done)
    latin = tmp_path / "latin.toml"
    latin.write_bytes(b'description = "Z\xfcrich"\n' + text.encode())
    done = cosim_inproc("run", str(latin), "--out", str(tmp_path / "b"), "--quiet")
    assert done.exit_code == 2 and "Traceback" not in done.stderr and no_traceback(done)
    assert f"{latin}: not UTF-8 text: byte 16 is 0xfc" in one_line(done)
