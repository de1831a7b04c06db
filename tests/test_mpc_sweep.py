"""Sweep: grid parsing, parallel runs equal to single runs, sweep.csv / sweep.png, CLI."""

from __future__ import annotations

import subprocess
import sys

import pandas as pd
import pytest

from cosim.run.simulate import run_scenario
from cosim.run.sweep import grid_points, parse_grid, run_sweep
from tests.cli_inproc import cosim_inproc


def test_parse_grid_ranges_lists_and_errors():
    grid = parse_grid(["controller.N=3..6", "controller.beta=1,2.5"])
    assert {k: list(v) for k, v in grid.items()} == {"controller.N": [3, 4, 5, 6],
                                                     "controller.beta": [1, 2.5]}
    assert len(grid_points(grid)) == 8
    assert grid_points(grid)[1] == {"controller.N": 3, "controller.beta": 2.5}
    for bad in ("controller.N", "controller.N=5..3", "controller.N=a..b", "=3"):
        with pytest.raises(ValueError):
            parse_grid([bad])


def test_a_grid_beyond_max_runs_is_refused_by_its_count():
    from cosim.run.grid import check_runs

    grid = parse_grid(["controller.N=1..1000000000", "controller.beta=1,2"])  # never listed
    with pytest.raises(ValueError) as err:
        check_runs(grid, 3, 10_000)
    assert str(err.value) == ("the sweep has 6,000,000,000 runs (2,000,000,000 grid points x 3 "
                              "scenario(s)), more than --max-runs 10,000: give --max-runs "
                              "6000000000 to run them all")
    with pytest.raises(ValueError, match=r"has 40 runs \(4 grid points x 1 scenario\(s\) x 10 "
                                         r"samples\), more than --max-runs 39:"):
        check_runs({"a": [1, 2], "b": range(2)}, 1, 39, samples=10)
    check_runs({"a": [1, 2], "b": range(2)}, 1, 40, samples=10)  # at the limit: allowed


def test_cli_sweep_refuses_a_huge_grid_before_any_work(tmp_path):
    for extra in ([], ["--perturb", "plant.mass=+-10%", "--samples", "1000"]):
        done = cosim_inproc("sweep", "seed000_stop_pid", "--set", "controller.kp=1..100000",
                            "--out", str(tmp_path), *extra)
        message = " ".join(done.stderr.split())
        assert done.exit_code == 2, done.stderr
        assert "more than --max-runs 10,000: give --max-runs" in message
        assert ("100,000,000 runs" if extra else "100,000 runs") in message
        assert not (tmp_path / "sweep.csv").exists() and not (tmp_path / "perturb.csv").exists()


def test_parallel_sweep_matches_single_runs(built_fmus, tmp_path):
    frame = run_sweep(["seed000_stop_rmpc", "seed000_stop_rsmpc"], {"controller.N": [3, 10]},
                      tmp_path, workers=2)
    assert len(frame) == 4
    written = pd.read_csv(tmp_path / "sweep.csv")
    assert list(written["controller.N"]) == [3, 10, 3, 10]
    assert (tmp_path / "sweep.png").read_bytes()[:4] == b"\x89PNG"
    single = run_scenario("seed000_stop_rsmpc", build=False, plot=False,
                          overrides={"controller.N": 3}).summary
    row = frame[(frame.scenario == "seed000_stop_rsmpc") & (frame["controller.N"] == 3)].iloc[0]
    # same scenario, same FMUs, same operations in another process: the same number
    assert row["stop_error_m"] == single["stop_error_m"]
    assert row["controller_executions"] == single["executions"]["controller"]
    assert row["command_switches"] == single["command_switches"]
    assert (frame["stop_error_m"].abs() <= 0.5).all()


def test_cli_sweep(built_fmus, tmp_path):
    done = subprocess.run([sys.executable, "-m", "cosim.cli", "sweep", "seed000_stop_rsmpc",
                           "--set", "controller.N=4..5", "--workers", "1", "--out",
                           str(tmp_path), "--format", "svg"], capture_output=True, text=True,
                          timeout=600)
    assert done.returncode == 0, done.stderr
    assert "sweep.csv" in done.stdout and (tmp_path / "sweep.svg").stat().st_size > 0
    assert max(len(line) for line in done.stdout.splitlines()) <= 80
    assert "sweep: 2/2 runs" in done.stderr and "ETA" in done.stderr  # progress
    assert len(pd.read_csv(tmp_path / "sweep.csv")) == 2
    bad = cosim_inproc("sweep", "seed000_stop_rsmpc", "--set", "controller.N=9..x")
    assert bad.exit_code == 2 and "range needs integers" in bad.stderr
