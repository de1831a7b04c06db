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
    assert "plant.mass = -1 outside" in rows["error"][0]
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
