"""``cosim sweep --scheduler``: the grid on a Dask distributed cluster (a LocalCluster of two
worker processes, reached by its address) gives the rows of the local pool, with the FMUs
uploaded or read from a shared path; failed points, --resume and the errors as locally."""

from __future__ import annotations

import logging
import sys

import pandas as pd
import pytest
from typer.testing import CliRunner

from cosim.cli import app
from cosim.run.sweep import run_sweep

distributed = pytest.importorskip("distributed")

TIMINGS = ["wall_time_s", "qp_solve_time_median_s"]  # measured, not computed
GRID = {"plant.mass": [-1.0, 470000.0, 490000.0]}  # -1: outside the parameter's range


def test_dask_in_process_cluster_gives_the_local_rows(built_fmus, tmp_path):
    """The cheap check of the default suite: a Dask cluster of one worker thread in this
    process (uploaded FMUs written, loaded and run there) gives the local pool's rows."""
    grid = {"plant.mass": [-1.0, 480000.0]}
    run_sweep("seed000_stop_pid", grid, tmp_path / "local", workers=1, plot=False)
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                                  dashboard_address=None, silence_logs=logging.ERROR) as c:
        run_sweep("seed000_stop_pid", grid, tmp_path / "dask", plot=False,
                  scheduler=c.scheduler_address)
    pd.testing.assert_frame_equal(_rows(tmp_path / "dask"), _rows(tmp_path / "local"))
    assert list(_rows(tmp_path / "dask")["status"]) == ["failed", "ok"]
    assert any("ato-cosim-fmus" in p for p in _extracted_fmus())


@pytest.fixture(scope="module")
def cluster():
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None, silence_logs=logging.ERROR) as c:
        yield c


def _rows(path) -> pd.DataFrame:
    return pd.read_csv(path / "sweep.csv", keep_default_na=False).drop(columns=TIMINGS)


def _extracted_fmus() -> list[str]:
    from cosim.run import master

    return [path for path, _ in master._EXTRACTED]


@pytest.mark.slow  # a LocalCluster of two processes starts in 5-20 s on the 2-core machine
def test_dask_rows_equal_the_local_pool(built_fmus, cluster, tmp_path):
    run_sweep("seed000_stop_pid", GRID, tmp_path / "local", workers=1, plot=False)
    local = _rows(tmp_path / "local")
    assert list(local["status"]) == ["failed", "ok", "ok"]
    assert "plant.mass = -1.0: must be at least" in local["error"][0]
    for shared in (False, True):
        out = tmp_path / f"dask_shared_{shared}"
        run_sweep("seed000_stop_pid", GRID, out, plot=False,
                  scheduler=cluster.scheduler_address, shared_fmus=shared)
        # the same FMUs, parameters and operations in other processes: the same numbers
        pd.testing.assert_frame_equal(_rows(out), local)
    with distributed.Client(cluster.scheduler_address) as client:
        extracted = [p for paths in client.run(_extracted_fmus).values() for p in paths]
    # the workers ran uploaded copies (<tmp>/ato-cosim-fmus/<sha256>.fmu) and the shared files
    assert any("ato-cosim-fmus" in p for p in extracted)
    assert str(built_fmus["BrakeDelayTrain"].path.resolve()) in extracted


@pytest.mark.slow
def test_dask_resume_and_interrupt_keep_the_finished_rows(built_fmus, cluster, tmp_path,
                                                           monkeypatch):
    run_sweep("seed000_stop_pid", {"plant.mass": [490000.0]}, tmp_path, workers=1,
              plot=False)
    first = pd.read_csv(tmp_path / "sweep.csv", keep_default_na=False)
    run_sweep("seed000_stop_pid", {"plant.mass": [490000.0, 480000.0]}, tmp_path,
              plot=False, resume=True, scheduler=cluster.scheduler_address)
    rows = pd.read_csv(tmp_path / "sweep.csv", keep_default_na=False)
    assert rows.iloc[0].to_dict() == first.iloc[0].to_dict()  # not run again
    assert list(rows["status"]) == ["ok", "ok"]

    # a SIGINT (the flag its handler sets) as soon as the first row is written
    from cosim.run import interrupt, sweep

    add = sweep.RowWriter.add

    def add_then_interrupt(self, row):
        add(self, row)
        interrupt._requested.append("SIGINT")

    monkeypatch.setattr(sweep.RowWriter, "add", add_then_interrupt)
    masses = [490000.0 + 1000.0 * k for k in range(12)]
    try:
        with pytest.raises(interrupt.Interrupted, match="the sweep interrupted"):
            run_sweep("seed000_stop_pid", {"plant.mass": masses}, tmp_path / "stopped",
                      plot=False, scheduler=cluster.scheduler_address)
    finally:
        interrupt._requested.clear()
    rows = pd.read_csv(tmp_path / "stopped" / "sweep.csv", keep_default_na=False)
    assert 1 <= len(rows) < 12 and set(rows["status"]) == {"ok"}


def test_scheduler_errors_name_the_fix(tmp_path, monkeypatch):
    """Usage errors (exit status 2) before anything runs."""
    def sweep(*args: str):
        return CliRunner().invoke(app, ["sweep", "seed000_stop_pid", "--no-plot", "--set",
                                        "plant.mass=490000", "--out", str(tmp_path), *args])

    result = sweep("--scheduler", "tcp://127.0.0.1:1", "--workers", "2")
    assert result.exit_code == 2 and "a cluster's workers are its own" in result.output
    result = sweep("--shared-fmus")
    assert result.exit_code == 2 and "--shared-fmus is for --scheduler" in result.output
    monkeypatch.setitem(sys.modules, "distributed", None)  # as if the extra were missing
    result = sweep("--scheduler", "local-dask")
    assert result.exit_code == 2, result.output
    assert "pip install 'ato-cosim[dask]'" in result.output.replace("\n", "")
    assert not (tmp_path / "sweep.csv").exists()
