"""Sweeps keep their good points: a row per point written as it finishes (status, error), a
failed point does not stop the others, an interrupted sweep keeps its finished rows,
``--resume`` skips the points already done, ``--workers 0`` is rejected."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
from typer.testing import CliRunner

from cosim.cli import app
from cosim.run import interrupt

ROOT = Path(__file__).resolve().parents[1]


def sweep(*args: str):
    return CliRunner().invoke(app, ["sweep", "seed000_stop_pid", "--no-plot", *args])


def test_a_failed_point_does_not_stop_the_others(built_fmus, tmp_path):
    result = sweep("--set", "plant.mass=-1,490000", "--workers", "2", "--out", str(tmp_path))
    assert result.exit_code == 1, result.output
    rows = pd.read_csv(tmp_path / "sweep.csv", keep_default_na=False)
    assert list(rows["status"]) == ["failed", "ok"]
    assert "plant.mass = -1: must be at least 1.0" in rows["error"][0]
    assert rows["error"][1] == "" and abs(float(rows["stop_error_m"][1])) < 0.5
    assert "failed: seed000_stop_pid plant.mass=-1" in result.output


def test_resume_runs_only_the_missing_points(built_fmus, tmp_path):
    assert sweep("--set", "plant.mass=490000", "--workers", "1",
                 "--out", str(tmp_path)).exit_code == 0
    first = pd.read_csv(tmp_path / "sweep.csv", keep_default_na=False)
    result = sweep("--set", "plant.mass=490000,500000", "--workers", "1", "--resume",
                   "--out", str(tmp_path))
    assert result.exit_code == 0, result.output
    rows = pd.read_csv(tmp_path / "sweep.csv", keep_default_na=False)
    assert list(rows["plant.mass"]) == [490000, 500000]
    # the first point was not run again: its row (wall time included) is the earlier one
    assert rows.iloc[0].to_dict() == first.iloc[0].to_dict()
    assert rows["status"].tolist() == ["ok", "ok"]


def test_workers_zero_is_rejected(tmp_path):
    result = sweep("--set", "plant.mass=490000", "--workers", "0", "--out", str(tmp_path))
    assert result.exit_code == 2 and "--workers" in result.output
    assert not (tmp_path / "sweep.csv").exists()


def test_interrupted_sweep_keeps_its_finished_rows(built_fmus, tmp_path):
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get(
        "PYTHONPATH", "")])}
    masses = ",".join(str(490000 + 1000 * k) for k in range(12))
    proc = subprocess.Popen([sys.executable, "-m", "cosim.cli", "sweep", "seed000_stop_pid",
                             "--set", f"plant.mass={masses}", "--workers", "1", "--no-plot",
                             "--out", str(tmp_path)], cwd=ROOT, env=env, text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    csv_path = tmp_path / "sweep.csv"
    deadline = time.monotonic() + 300
    while time.monotonic() < deadline and proc.poll() is None:  # until a row is written
        if csv_path.is_file() and len(csv_path.read_text().splitlines()) >= 2:
            break
        time.sleep(0.05)
    proc.send_signal(signal.SIGINT)
    _, stderr = proc.communicate(timeout=300)
    assert proc.returncode == interrupt.EXIT_INTERRUPTED, stderr
    assert "Traceback" not in stderr and "the finished rows are in" in stderr
    rows = pd.read_csv(csv_path, keep_default_na=False)
    assert 1 <= len(rows) < 12
    assert set(rows["status"]) <= {"ok", "interrupted"} and (rows["status"] == "ok").any()


def test_resume_after_a_failed_point_plots_and_keeps_numbers(built_fmus, tmp_path):
    """sweep.csv with a failed row has empty cells, so its columns read back as text: the
    resumed rows are numbers again (the plot draws them, counts stay integers)."""
    first = CliRunner().invoke(app, ["sweep", "seed000_stop_pid", "--set", "plant.mass=-1,490000",
                                     "--workers", "1", "--out", str(tmp_path)])
    assert first.exit_code == 1, first.output
    result = CliRunner().invoke(app, ["sweep", "seed000_stop_pid", "--set",
                                      "plant.mass=490000,500000", "--workers", "1", "--resume",
                                      "--out", str(tmp_path)])
    assert result.exit_code == 0, result.output
    assert (tmp_path / "sweep.png").is_file()
    rows = pd.read_csv(tmp_path / "sweep.csv")
    assert list(rows["plant.mass"]) == [490000, 500000]
    assert rows["command_switches"].dtype.kind == "i"
    assert rows["stop_error_m"].dtype.kind == "f"


def test_a_bad_grid_value_is_refused_before_any_point_runs(built_fmus, tmp_path):
    """controller.N=abc (N is an Integer) fails at once naming the --set option; the good
    point 20 is not run first."""
    result = CliRunner().invoke(app, ["sweep", "seed000_stop_mpc", "--no-plot", "--set",
                                      "controller.N=20,abc", "--out", str(tmp_path)])
    assert result.exit_code == 2, result.output
    assert "--set controller.N=abc: controller.N is Integer, got 'abc'" in " ".join(
        result.output.split())
    assert not (tmp_path / "sweep.csv").exists()


def test_resume_reruns_a_torn_row(built_fmus, tmp_path):
    """A row cut short (a full disk) lacks its last field, the inputs' digest: not kept."""
    from cosim.run.sweep import run_sweep

    out = tmp_path / "out"
    first = run_sweep("seed000_stop_pid", {"plant.mass": [490000]}, out, workers=1,
                      plot=False)
    text = (out / "sweep.csv").read_text()
    assert "\r" not in text
    header, row = text.splitlines()
    (out / "sweep.csv").write_text(f"{header}\n{row[:row.index('.') + 3]}\n")  # mid-number
    again = run_sweep("seed000_stop_pid", {"plant.mass": [490000]}, out, workers=1,
                      plot=False, resume=True)
    assert again["status"].tolist() == ["ok"]
    assert again["stop_error_m"][0] == first["stop_error_m"][0]
    assert again["wall_time_s"][0] != first["wall_time_s"][0]  # run again: its own timing


def test_the_digest_follows_the_scenario_content_and_the_point(tmp_path):
    from cosim.run.sweep import inputs_digest

    path = tmp_path / "s.toml"
    path.write_text("[simulation]\nstop_time = 1.0\n")
    first = inputs_digest(str(path), {"controller.N": 3})
    assert inputs_digest(str(path), {"controller.N": 4}) != first
    path.write_text("[simulation]\nstop_time = 2.0\n")  # edited: ref_decel 0.5 -> 0.4 alike
    assert inputs_digest(str(path), {"controller.N": 3}) != first


def test_resume_reruns_a_row_of_other_inputs(built_fmus, tmp_path):
    """A row whose digest is not today's (the scenario was edited since) is run again."""
    from cosim.run.sweep import run_sweep

    out = tmp_path / "out"
    first = run_sweep("seed000_stop_pid", {"plant.mass": [490000]}, out, workers=1,
                      plot=False)
    rows = pd.read_csv(out / "sweep.csv", keep_default_na=False, dtype=str)
    rows.loc[0, "stop_error_m"], rows.loc[0, "inputs_digest"] = "9.99", "0" * 16
    rows.to_csv(out / "sweep.csv", index=False)
    again = run_sweep("seed000_stop_pid", {"plant.mass": [490000]}, out, workers=1,
                      plot=False, resume=True)
    assert again["stop_error_m"][0] == first["stop_error_m"][0]
    assert again["inputs_digest"][0] == first["inputs_digest"][0]
