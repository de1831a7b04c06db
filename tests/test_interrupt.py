"""SIGINT/SIGTERM during ``cosim run``: partial results, summary and plot are written, one line
is printed, the exit status is 130; a complete earlier run is never replaced by a partial one."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from cosim.run import interrupt
from cosim.run.simulate import run_scenario

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = "seed000_stop_pid"
SHORT = ["--set", "simulation.stop_time=120"]  # the stop, then a minute standing


def start(out: Path, *extra: str) -> subprocess.Popen:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get(
        "PYTHONPATH", "")])}
    return subprocess.Popen([sys.executable, "-m", "cosim.cli", "run", SCENARIO, "--out",
                             str(out), *SHORT, *extra], cwd=ROOT, env=env, text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)


def wait_started(proc: subprocess.Popen) -> list[str]:
    """Read stderr up to the command's first line (printed once the signals are guarded)."""
    lines = [proc.stderr.readline()]
    assert lines[0].startswith("cosim run"), lines[0] + proc.stderr.read()
    return lines


def check_outcome(proc: subprocess.Popen, out: Path, first: list[str]) -> bool:
    """Either the run finished before the signal (status 0, complete) or it was interrupted:
    status 130, exactly one line saying so, and readable partial files. True if interrupted."""
    stdout, stderr = proc.communicate(timeout=120)
    lines = [*first, *stderr.splitlines()]
    assert "Traceback" not in stderr, stderr
    summary = json.loads((out / "summary.json").read_text())
    frame = pd.read_csv(out / "results.csv")
    assert (out / "plot.png").read_bytes()[:4] == b"\x89PNG"
    if proc.returncode in (0, -signal.SIGINT, -signal.SIGTERM):
        # finished first; a signal during the interpreter's own shutdown (after everything is
        # written, when Python has reset its handlers) ends the process the default way
        assert summary["completed"] is True
        return False
    assert proc.returncode == interrupt.EXIT_INTERRUPTED, stderr
    said = [line for line in lines if line.startswith("interrupted")]
    assert len(said) == 1 and "written to" in said[0], lines
    assert stdout == ""
    assert summary["completed"] is False
    assert summary["error"].startswith("interrupted at t = ")
    t_stop = float(summary["error"].split("=")[1].split()[0])
    assert summary["sim_time_s"] == pytest.approx(t_stop)
    assert list(frame.columns[:1]) == ["time"]
    if len(frame):
        assert frame["time"].iloc[-1] <= t_stop + 1e-9  # nothing recorded after the stop
    return True


def _reference_durations(tmp_path: Path) -> tuple[float, float]:
    """Seconds from the command's first line to the end of the simulation (its 100 % line) and
    to its exit, uninterrupted: only to spread the signal times; nothing is asserted on them."""
    proc = start(tmp_path / "ref")
    wait_started(proc)
    t0 = time.monotonic()
    for line in proc.stderr:
        if "(100 %)" in line:
            break
    t_end = time.monotonic() - t0
    proc.communicate(timeout=120)
    assert proc.returncode == 0
    return t_end, time.monotonic() - t0


def _trials(tmp_path: Path, n: int, seed: int, whole: bool) -> int:
    """``n`` runs, each sent SIGINT or SIGTERM after a seeded random delay, up to the end of the
    simulation or (``whole``, every other run) up to the exit, writing included: the number of
    runs interrupted (the others finished first; how many depends on the machine's load)."""
    rng = np.random.default_rng(seed)
    t_end, t_exit = _reference_durations(tmp_path)
    interrupted = 0
    for k in range(n):
        out = tmp_path / f"run{k}"
        proc = start(out)
        first = wait_started(proc)
        time.sleep(rng.uniform(0.0, t_exit if whole and k % 2 else t_end))
        proc.send_signal(rng.choice([signal.SIGINT, signal.SIGTERM]))
        interrupted += check_outcome(proc, out, first)
    return interrupted


def test_signals_at_random_times_always_leave_readable_results(built_fmus, tmp_path):
    assert _trials(tmp_path, 3, seed=12, whole=False) >= 1


@pytest.mark.slow
def test_twenty_signals_at_random_times(built_fmus, tmp_path):
    assert _trials(tmp_path, 20, seed=2026, whole=True) >= 1


def test_second_signal_exits_at_once(built_fmus, tmp_path):
    proc = start(tmp_path / "out", "--set", "simulation.stop_time=100000")
    wait_started(proc)
    time.sleep(0.5)
    proc.send_signal(signal.SIGINT)
    time.sleep(0.3)  # two signals at once would be one for Python
    proc.send_signal(signal.SIGINT)
    _, stderr = proc.communicate(timeout=120)
    assert proc.returncode == interrupt.EXIT_INTERRUPTED
    assert "Traceback" not in stderr
    assert "interrupted again: exiting at once" in stderr


def _interrupt_at(t_interrupt: float):
    """A progress callback that sends this process a real SIGINT once sim time passes t."""
    sent = []

    def progress(t: float, _total: float) -> None:
        if t >= t_interrupt and not sent:
            sent.append(t)
            os.kill(os.getpid(), signal.SIGINT)

    return progress


@pytest.fixture
def main_thread():
    if threading.current_thread() is not threading.main_thread():
        pytest.skip("signals reach the main thread only")


def test_partial_run_never_replaces_a_complete_one(built_fmus, tmp_path, main_thread):
    out = tmp_path / "run"
    handler = signal.getsignal(signal.SIGINT)  # the host's (ignored in a background job)
    complete = run_scenario(SCENARIO, out_dir=out, build=False, plot=False)
    before = (out / "results.csv").read_bytes()
    with pytest.raises(interrupt.Interrupted) as err:
        run_scenario(SCENARIO, out_dir=out, build=False, plot=False,
                     progress=_interrupt_at(10.0))
    # stopped at the first progress report after the signal (the next point on the Python
    # loop, a later one on the C loop)
    found = re.match(r"interrupted at t = ([0-9.]+) s \(SIGINT\)", str(err.value))
    assert found and float(found.group(1)) > 10.0, str(err.value)
    assert (out / "results.csv").read_bytes() == before  # the complete run is untouched
    partial = json.loads((tmp_path / "run.partial" / "summary.json").read_text())
    assert partial["completed"] is False
    assert partial["sim_time_s"] == pytest.approx(float(found.group(1)))
    assert complete.summary["completed"] is True
    # with force, the partial result replaces it
    with pytest.raises(interrupt.Interrupted):
        run_scenario(SCENARIO, out_dir=out, build=False, plot=False, force=True,
                     progress=_interrupt_at(10.0))
    assert json.loads((out / "summary.json").read_text())["completed"] is False
    assert signal.getsignal(signal.SIGINT) is handler  # restored


@pytest.mark.parametrize("kind", ["file", "under_file", "unwritable"])
def test_bad_out_is_rejected_before_the_run(tmp_path, kind):
    from typer.testing import CliRunner

    from cosim.cli import app

    a_file = tmp_path / "a_file"
    a_file.write_text("x")
    target = {"file": a_file, "under_file": a_file / "sub" / "dir",
              "unwritable": Path("/proc/cosim-test-out")}[kind]
    ssp = tmp_path if kind == "file" else target / "x.ssp"  # a folder where a file should be
    for args, named in ((["run", SCENARIO, "--out", str(target), "--no-plot"], target),
                        (["sweep", SCENARIO, "--set", "controller.kp=1,2", "--out",
                          str(target)], target),
                        (["export", SCENARIO, "--ssp", str(ssp)], ssp)):
        result = CliRunner().invoke(app, args)
        assert result.exit_code == 2, (args, result.output)
        assert "error:" in result.output and str(named) in result.output, result.output
        assert result.exception is None or isinstance(result.exception, SystemExit)
