"""``cosim run`` and ``cosim sweep`` with FMUs that crash or hang (hostile.c, built by the
tests): the FMUs run in child processes, so a crash is reported with the FMU, the signal, the
FMI call and the time, a hang ends on a signal, and no child outlives its parent. Every wait
is bounded and generous: none decides the outcome."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import psutil
import pytest

ROOT = Path(__file__).resolve().parents[2]
BOUND_S = 120.0  # s, a bound no healthy step here comes near, even on a loaded machine
# s, a sweep point's time limit: long enough for a forked worker to reach the FMU call that
# blocks even on a busy machine (a limit that expires before the call names no FMU)
LIMIT_S = 10.0

CRASHES = {"SegfaultInDoStep": "crashed with SIGSEGV", "AbortInDoStep": "crashed with SIGABRT",
           "ExitInDoStep": "exited with status 3"}


def scenario(tmp_path: Path, fmu: Path, stop: float = 1.0) -> Path:
    """One hostile FMU alone, u = 0.5, steps of 0.125 s."""
    path = tmp_path / f"{fmu.stem}.toml"
    path.write_text(f'[simulation]\nstop_time = {stop!r}\noutput_interval = 0.125\n'
                    f'algorithm = "event"\nbase_step = 0.125\n[fmus.h]\nfmu = "{fmu}"\n'
                    '[fmus.h.parameters]\n[fmus.h.inputs]\nu = 0.5\n[connections]\n')
    return path


def cosim(*args: str, **popen: object) -> subprocess.Popen:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.Popen([sys.executable, "-m", "cosim.cli", *args], cwd=ROOT, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            **popen)


def until(condition: Callable[[], object], what: str) -> object:
    """Poll ``condition`` until it is true, failing after :data:`BOUND_S`."""
    end = time.monotonic() + BOUND_S
    while time.monotonic() < end:
        value = condition()
        if value:
            return value
        time.sleep(0.1)
    raise AssertionError(f"not within {BOUND_S} s: {what}")


def in_fmu(parent: subprocess.Popen, fmu: str) -> psutil.Process:
    """The child of ``parent`` once it has loaded the FMU's binary ``fmu``.so and has had a
    second to reach its first doStep (microseconds of work)."""

    def loaded() -> psutil.Process | None:
        for child in psutil.Process(parent.pid).children():
            try:
                if any(m.path.endswith(f"{fmu}.so") for m in child.memory_maps()):
                    return child
            except psutil.Error:
                pass
        return None

    child = until(loaded, f"a child of {parent.pid} with {fmu}.so loaded")
    time.sleep(1.0)
    return child  # type: ignore[return-value]


def gone(pid: int) -> bool:
    try:
        return psutil.Process(pid).status() == psutil.STATUS_ZOMBIE
    except psutil.NoSuchProcess:
        return True


@pytest.mark.parametrize("name", sorted(CRASHES))
def test_a_crashing_fmu_is_reported_and_no_stale_results_stay(hostile_fmus, tmp_path, name):
    out = tmp_path / "out"
    out.mkdir()
    (out / "results.csv").write_text("time,h.y\n0.0,1.0\n")  # an earlier, partial run
    (out / "summary.json").write_text(json.dumps({"completed": False, "error": "earlier"}))
    proc = cosim("run", str(scenario(tmp_path, hostile_fmus[name])), "--out", str(out), "-q")
    _, err = proc.communicate(timeout=BOUND_S)
    message = f"FMU h {CRASHES[name]} in fmi2DoStep at t = 0 s"
    assert proc.returncode == 2, err
    assert message in err, err
    assert not (out / "results.csv").exists()
    summary = json.loads((out / "summary.json").read_text())
    assert summary["completed"] is False and summary["error"].startswith(message)


def test_a_crash_keeps_a_complete_earlier_run(hostile_fmus, tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "results.csv").write_text("time,h.y\n0.0,1.0\n")
    (out / "summary.json").write_text(json.dumps({"completed": True}))
    proc = cosim("run", str(scenario(tmp_path, hostile_fmus["SegfaultInDoStep"])), "--out",
                 str(out), "-q")
    _, err = proc.communicate(timeout=BOUND_S)
    assert proc.returncode == 2 and "crashed with SIGSEGV" in err, err
    assert json.loads((out / "summary.json").read_text()) == {"completed": True}
    crash = json.loads((tmp_path / "out.partial" / "summary.json").read_text())
    assert crash["completed"] is False and "SIGSEGV" in crash["error"]


@pytest.mark.parametrize("name", ["BlockInDoStep", "SpinInDoStep"])
def test_sigterm_ends_a_run_whose_fmu_hangs(hostile_fmus, tmp_path, name):
    out = tmp_path / "out"
    proc = cosim("run", str(scenario(tmp_path, hostile_fmus[name])), "--out", str(out), "-q")
    child = in_fmu(proc, name)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=BOUND_S)
    assert proc.returncode == 130, err
    assert "FMU h did not return from fmi2DoStep at t = 0 s after SIGTERM" in err, err
    assert until(lambda: gone(child.pid), "the child ended")
    assert json.loads((out / "summary.json").read_text())["completed"] is False


def test_a_second_interrupt_ends_the_run_and_its_child_at_once(hostile_fmus, tmp_path):
    proc = cosim("run", str(scenario(tmp_path, hostile_fmus["BlockInDoStep"])), "--out",
                 str(tmp_path / "out"), "-q")
    child = in_fmu(proc, "BlockInDoStep")
    proc.send_signal(signal.SIGINT)
    proc.send_signal(signal.SIGTERM)  # two kinds: the kernel keeps both pending
    _, err = proc.communicate(timeout=BOUND_S)
    assert proc.returncode == 130, err
    assert "interrupted again" in err, err
    assert until(lambda: gone(child.pid), "the child ended")


def test_no_child_outlives_a_killed_parent(hostile_fmus, tmp_path):
    proc = cosim("run", str(scenario(tmp_path, hostile_fmus["BlockInDoStep"])), "--out",
                 str(tmp_path / "out"), "-q")
    child = in_fmu(proc, "BlockInDoStep")
    proc.kill()
    proc.communicate(timeout=BOUND_S)
    assert until(lambda: gone(child.pid), "the child of a killed parent ended")


def test_a_sweep_point_whose_worker_crashes_names_the_signal_and_the_fmu(hostile_fmus,
                                                                          tmp_path):
    """Through the CLI, as a user runs it: a sweep forked from this test's process would
    inherit pytest's fault handler, and each deliberate crash would print its worker's Python
    stack on the terminal beside the test report."""
    import pandas as pd

    paths = [str(scenario(tmp_path, hostile_fmus[name]))
             for name in ("SegfaultInDoStep", "SlowFirstStep")]
    out = tmp_path / "sweep"
    proc = cosim("sweep", *paths, "--set", "simulation.stop_time=1,0.5", "--workers", "2",
                 "--out", str(out), "--no-plot")
    _, err = proc.communicate(timeout=BOUND_S)
    assert proc.returncode == 1, err  # a failed point: exit status 1 once the others end
    rows = {(r["scenario"], r["simulation.stop_time"]): r
            for r in pd.read_csv(out / "sweep.csv").to_dict("records")}
    for u in (1.0, 0.5):
        crashed = rows[("SegfaultInDoStep", u)]
        assert crashed["status"] == "failed"
        assert crashed["error"] == "FMU h crashed with SIGSEGV in fmi2DoStep at t = 0 s"
        assert rows[("SlowFirstStep", u)]["status"] == "ok", rows


def test_a_sweep_point_over_its_time_limit_is_stopped(hostile_fmus, tmp_path):
    from cosim.run.sweep import run_sweep

    path = str(scenario(tmp_path, hostile_fmus["BlockInDoStep"]))
    frame = run_sweep(path, {"simulation.stop_time": [1.0]}, tmp_path / "sweep", workers=1,
                      plot=False, time_limit=LIMIT_S)
    [row] = frame.to_dict("records")
    assert row["status"] == "failed"
    assert row["error"] == (f"stopped after its time limit of {LIMIT_S:g} s: FMU h in "
                            "fmi2DoStep at t = 0 s")


def test_no_sweep_worker_outlives_a_killed_sweep(hostile_fmus, tmp_path):
    proc = cosim("sweep", str(scenario(tmp_path, hostile_fmus["BlockInDoStep"])), "--set",
                 "simulation.stop_time=1,2", "--workers", "2", "--out", str(tmp_path / "sweep"),
                 "--no-plot")

    def both() -> list[psutil.Process]:
        found = [c for c in psutil.Process(proc.pid).children()
                 if any(m.path.endswith("BlockInDoStep.so") for m in _maps(c))]
        return found if len(found) == 2 else []

    workers = until(both, "two sweep workers in the FMU")
    proc.kill()
    proc.communicate(timeout=BOUND_S)
    for worker in workers:  # type: ignore[union-attr]
        assert until(lambda w=worker: gone(w.pid), f"worker {worker.pid} ended")


def _maps(process: psutil.Process) -> list:
    try:
        return process.memory_maps()
    except psutil.Error:
        return []


def test_a_nan_output_is_a_warning_naming_the_variable_and_time(hostile_fmus, tmp_path):
    """NanOutput's y is NaN from t = 0.25 s: of the points 0, 0.125, .., 1 s, 7 are NaN."""
    from cosim.run.simulate import run_scenario

    result = run_scenario(scenario(tmp_path, hostile_fmus["NanOutput"]), build=False,
                          plot=False)
    assert result.summary["warnings"] == [
        "h.y is nan from t = 0.25 s on (7 of 9 recorded points are NaN or infinite)"]


def test_a_sweep_calls_a_third_party_fmu_only_in_its_workers(hostile_fmus, tmp_path):
    """The sweep's warm-up (before its workers fork) only extracts an FMU that is not one of
    the package's Python builds: one that blocks in fmi2Instantiate stops its point at the
    time limit, in a worker, and the sweep ends (with the warm-up calling it, the sweep's own
    process would block)."""
    import pandas as pd

    out = tmp_path / "sweep"
    proc = cosim("sweep", str(scenario(tmp_path, hostile_fmus["BlockInInstantiate"])), "--set",
                 "simulation.stop_time=1", "--workers", "1", "--time-limit", str(LIMIT_S),
                 "--out", str(out), "--no-plot")
    try:
        proc.communicate(timeout=BOUND_S)
    except subprocess.TimeoutExpired:
        for child in psutil.Process(proc.pid).children(recursive=True):
            child.kill()
        proc.kill()
        proc.communicate()
        raise AssertionError(f"the sweep did not end within {BOUND_S} s") from None
    [row] = pd.read_csv(out / "sweep.csv").to_dict("records")
    assert row["status"] == "failed"
    assert row["error"].startswith(f"stopped after its time limit of {LIMIT_S:g} s: FMU h in "
                                   "fmi2Instantiate"), row["error"]
