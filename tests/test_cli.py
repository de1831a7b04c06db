"""The `cosim` command end to end: runs as a user runs them (in a subprocess); error messages
read in this process through typer's test runner (the text a process prints)."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

from tests.cli_inproc import cosim_inproc, no_traceback


def cosim(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "cosim.cli", *args], capture_output=True,
                          text=True, timeout=600)


def test_run_writes_results_summary_and_plot(built_fmus, tmp_path):
    done = cosim("run", "seed000_stop_pid", "--out", str(tmp_path))
    assert done.returncode == 0, done.stderr
    assert "stop_error_m" in done.stdout
    summary = json.loads((tmp_path / "summary.json").read_text())
    for key in ("stop_error_m", "final_speed_mps", "command_switches", "executions",
                "do_steps", "wall_time_s", "sim_time_s"):
        assert key in summary
    assert abs(summary["stop_error_m"]) < 0.5
    frame = pd.read_csv(tmp_path / "results.csv")
    assert frame.columns[0] == "time"
    assert frame["time"].iloc[-1] == pytest.approx(60.0)
    png = (tmp_path / "plot.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 10_000


def test_run_with_set_and_algorithm(built_fmus, tmp_path):
    done = cosim("run", "seed000_stop_pid", "--out", str(tmp_path), "--algorithm", "fixed",
                 "--set", "simulation.stop_time=10", "--set", "plant.v0=15", "--no-plot")
    assert done.returncode == 0, done.stderr
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["algorithm"] == "fixed"
    assert summary["sim_time_s"] == pytest.approx(10.0)
    assert not (tmp_path / "plot.png").exists()


@pytest.mark.parametrize("args,message", [
    (("run", "seed000_stop_pdi"), "did you mean 'seed000_stop_pid'"),
    (("run", "seed000_stop_pid", "--set", "plant.mass=-1"), "mass = -1: must be at least 1.0"),
    (("run", "seed000_stop_pid", "--set", "plant.nope=1"), "no variable 'nope'"),
    (("build", "NoSuchFmu"), "unknown FMU"),
])
def test_errors_are_one_clear_line(built_fmus, tmp_path, monkeypatch, args, message):
    monkeypatch.chdir(tmp_path)
    done = cosim_inproc(*args)
    assert done.exit_code == 2
    assert message in done.stderr.replace("\n", " ")
    assert "Traceback" not in done.stderr and no_traceback(done), done.exception


def test_list_and_validate(built_fmus):
    """``cosim list`` names the FMUs and scenarios; ``cosim validate`` passes our FMUs, each
    report saying PASSED with no error."""
    listed = cosim("list")
    assert listed.returncode == 0
    assert "BrakeDelayTrain" in listed.stdout and "seed000_stop_pid" in listed.stdout
    checked = cosim("validate", "BrakeDelayTrain", "StopPid")
    assert checked.returncode == 0, checked.stdout + checked.stderr
    assert "problem" not in checked.stdout
    assert "FAIL" not in checked.stdout, checked.stdout
    reports = re.split(r"^FMU ", checked.stdout, flags=re.M)[1:]
    assert [Path(r.split()[0]).stem for r in reports] == ["BrakeDelayTrain", "StopPid"], reports
    assert all("PASSED: 0 error(s)" in r for r in reports), checked.stdout


def test_error_keeps_the_scenario_keys(built_fmus, tmp_path):
    """Scenario keys in brackets are printed as written (not taken as console markup)."""
    done = cosim_inproc("run", "seed000_stop_pid", "--algorithm", "fixed", "--set",
                        "simulation.base_step=1.0", "--set", "simulation.output_interval=1.0",
                        "--out", str(tmp_path / "x"))
    assert done.exit_code == 2
    assert ("[fmus.controller] sample_time = 0.2 s is not a multiple of [simulation] "
            "base_step = 1.0 s") in " ".join(done.stderr.split() + done.stdout.split())


def test_printed_summary_has_the_family_metrics_and_fits_80_columns() -> None:
    """Every scalar metric the scenario's [summary] produced is printed (seed 002's speed error
    outside the stop window too), bookkeeping stays in summary.json, and the table fits 80
    columns."""
    import io

    from rich.console import Console

    from cosim import cli

    summary = {"completed": True, "algorithm": "event", "warnings": [], "stop_error_m": 0.5,
               "max_abs_speed_error_outside_stop_kmh": 0.64, "executions": {"plant": 7},
               "command_switch_resolution": 1e-6, "real_time_factor": 462.1,
               "scenario": "x" * 200}
    rows = dict(cli.summary_rows(summary))
    assert rows["max_abs_speed_error_outside_stop_kmh"] == "0.64"
    assert rows["executions"] == "plant=7"
    assert not {"completed", "algorithm", "warnings", "command_switch_resolution"} & set(rows)
    buffer = io.StringIO()
    old = cli.out
    cli.out = Console(file=buffer, width=120)
    try:
        cli.print_summary(summary, "title")
    finally:
        cli.out = old
    assert max(len(line) for line in buffer.getvalue().splitlines()) <= 80
    assert "0.64" in buffer.getvalue()


def test_starting_the_cli_imports_no_numerics() -> None:
    """``import cosim.cli`` (every command's start, ``--help`` included) imports neither numpy
    nor the scenario and build modules: each command imports what it uses when it runs."""
    heavy = ("numpy", "pandas", "scipy", "fmpy", "matplotlib", "cosim.run.scenario",
             "cosim.build.native")
    code = f"import sys, cosim.cli; print([m for m in {heavy!r} if m in sys.modules])"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, cwd=Path(__file__).resolve().parents[1])
    assert out.stdout.strip() == "[]"
