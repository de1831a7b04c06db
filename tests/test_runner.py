"""The shared runner (cosim/run/runner.py) of sweeps and reproductions: results and failures
handed on per task, the environment of spawned workers, and the refusals of --workers."""

from __future__ import annotations

import os

import pytest

from cosim.run import runner

VAR = "ATO_COSIM_RUNNER_TEST"


def test_a_failing_task_fails_alone_and_workers_get_the_environment():
    tasks = [runner.Task("env 1", os.getenv, (VAR,)), runner.Task("bad", int, ("abc",)),
             runner.Task("env 2", os.getenv, (VAR,))]
    results, errors = {}, {}
    runner.run_tasks(tasks, lambda t, r: results.__setitem__(t.key, r),
                     lambda t, e: errors.__setitem__(t.key, e), workers=2,
                     env={VAR: "spawned"}, quiet=True)
    assert results == {"env 1": "spawned", "env 2": "spawned"}
    assert list(errors) == ["bad"] and isinstance(errors["bad"], ValueError)
    assert VAR not in os.environ  # set for the workers only


def test_in_process_with_one_worker():
    seen = []
    runner.run_tasks([runner.Task(i, abs, (-i,)) for i in range(3)],
                     lambda t, r: seen.append((t.key, r)), lambda t, e: None, workers=1,
                     quiet=True)
    assert seen == [(0, 0), (1, 1), (2, 2)]


@pytest.mark.parametrize("workers,scheduler,says", [
    (0, None, "--workers 0: must be at least 1"),
    (2, "tcp://10.0.0.5:8786", "a cluster's workers are its own"),
])
def test_worker_options_are_checked(workers, scheduler, says):
    if scheduler is not None:
        pytest.importorskip("distributed")
    with pytest.raises(ValueError, match=says):
        runner.check_workers(workers, scheduler)


def test_one_runner_starts_every_pool_and_cluster():
    """Sweeps, reproductions, ensembles and --perturb studies go through cosim.run.runner:
    no other module of cosim/run starts a process pool or a Dask cluster."""
    from pathlib import Path

    import cosim.run

    starters = ("ProcessPoolExecutor(", "LocalCluster(", "Client(", "multiprocessing.Pool(")
    found = [f"{p.name}: {s}" for p in sorted(Path(cosim.run.__file__).parent.rglob("*.py"))
             if p.name != "runner.py" for s in starters if s in p.read_text()]
    assert found == []
