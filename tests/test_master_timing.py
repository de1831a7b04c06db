"""Master timing not exercised by the shipped scenarios: a start time other than 0, an
instance's ``max_step``, an FMU announcing a next event that is not in the future."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from cosim.fmu.state import to_ticks
from cosim.run import master as master_mod
from cosim.run.master import SimulationError, native_loop
from cosim.run.scenario import load_scenario
from cosim.run.simulate import run_scenario

PID = "seed000_stop_pid"


def _run(overrides=(), algorithm=None, record=("controller.next_event_time",), **kw):
    sc = load_scenario(PID, list(overrides))
    sc.record = [*sc.record, *record]
    return run_scenario(sc, algorithm=algorithm, build=False, plot=False, **kw)


@pytest.fixture(scope="module")
def from_zero(built_fmus):
    return _run()


@pytest.mark.parametrize("t0", [100.0, 1e6 + 0.1])
def test_start_time_offsets_results_and_events_exactly(from_zero, t0):
    """The same 60 s from t0 (on the plant's absolute sub-step grid, multiples of its 0.01 s
    max_step): the same trajectory bit for bit, every recorded time and every announced event
    exactly t0 later in integer nanoseconds (1e6 s + 0.1 s is not exact in binary: the
    tick grid is), the same counts; the summary's sim_time_s is the simulated span."""
    r = _run([f"simulation.start_time={t0}", f"simulation.stop_time={t0 + 60.0}"])
    a, b = from_zero.frame, r.frame
    offset = to_ticks(t0)
    assert [to_ticks(x) - to_ticks(y) for x, y in zip(b["time"], a["time"])] == \
        [offset] * len(a)
    assert [to_ticks(x) - to_ticks(y) for x, y in zip(b["controller.next_event_time"],
                                                      a["controller.next_event_time"])] == \
        [offset] * len(a)
    assert to_ticks(a["controller.next_event_time"].iloc[0]) == to_ticks(0.2)
    for col in a.columns.drop(["time", "controller.next_event_time"]):
        assert list(b[col]) == list(a[col]), col
    assert r.summary["sim_time_s"] == 60.0
    assert r.executions == from_zero.executions and r.do_steps == from_zero.do_steps
    assert r.summary["stop_error_m"] == from_zero.summary["stop_error_m"]


def test_start_time_off_the_substep_grid(from_zero):
    """A start at 1234.5678 s is off the plant's 0.01 s sub-step grid (anchored at t = 0): the
    first sub-step of each step is split, which changes the discretisation only (6e-7 m on
    the stop here; checked to 1 mm, the pinned PID figure's tolerance); times stay exact."""
    t0 = 1234.5678
    r = _run([f"simulation.start_time={t0}", f"simulation.stop_time={t0 + 60.0}"])
    assert [to_ticks(x) for x in r.frame["time"]] == \
        [to_ticks(x) + to_ticks(t0) for x in from_zero.frame["time"]]
    assert r.summary["stop_error_m"] == pytest.approx(from_zero.summary["stop_error_m"],
                                                      abs=1e-3)
    assert r.executions == from_zero.executions


def _steps(monkeypatch) -> dict[str, list[tuple[int, int]]]:
    """Record every doStep (start, size) in ticks, per instance."""
    log: dict[str, list[tuple[int, int]]] = {}
    real = master_mod.FmuUnit._do_step
    # the Python loop's calls (the C loop makes the same ones: tests/third_party/
    # test_native_loop.py)
    monkeypatch.setenv(native_loop.ENV, "off")

    def do_step(self, t, h):
        log.setdefault(self.name, []).append((t, h))
        return real(self, t, h)

    monkeypatch.setattr(master_mod.FmuUnit, "_do_step", do_step)
    return log


@pytest.mark.parametrize("algorithm, instance, max_step, steps", [
    ("event", "plant", 0.05, {"plant": 1200, "controller": 300}),
    ("event", "controller", 0.1, {"plant": 300, "controller": 600}),
    ("fixed", "plant", 0.05, {"plant": 1200, "controller": 300}),
    ("jacobi", "plant", 0.07, {"plant": 900, "controller": 300}),  # 0.07 + 0.07 + 0.06
])
def test_instance_max_step_bounds_every_step(from_zero, monkeypatch, algorithm, instance,
                                             max_step, steps):
    """``[fmus.X] max_step``: no doStep of X is longer, under every algorithm (the event
    master adds communication points for a plant; a controller, or any FMU inside a fixed
    base step, is stepped in pieces with its inputs held). The controller still computes
    once per event; on the plant's 0.01 s sub-step grid the trajectory is the same to
    rounding (1e-9, as tests/test_brake_delay.py's step-size independence)."""
    log = _steps(monkeypatch)
    r = _run([f"{instance}.max_step={max_step}"], algorithm=algorithm, record=())
    limit = to_ticks(max_step)
    assert max(h for _, h in log[instance]) == limit
    assert {k: len(v) for k, v in log.items()} == steps == r.do_steps
    for name, calls in log.items():  # contiguous: each step starts where the last ended
        assert all(t1 == t0 + h0 for (t0, h0), (t1, _) in zip(calls, calls[1:])), name
    assert r.executions["controller"] == 301
    if algorithm != "jacobi":
        diff = (r.frame.set_index("time") - from_zero.frame.set_index("time")[
            r.frame.columns[1:]]).abs().max().max()
        assert diff < 1e-9


@pytest.mark.parametrize("announced", ["present", "past", "nan"])
def test_next_event_time_not_in_the_future_is_an_error(built_fmus, tmp_path, monkeypatch,
                                                       announced):
    """A controller announcing, at its event at t = 2 s, a next event at 2 s (present),
    1.8 s (past) or NaN: the run stops with an error naming the instance and both times
    (never clamped to the next step, which would hide the FMU's fault), and what was
    recorded until then is written."""
    real_update = master_mod.FmuUnit.update_schedule
    fault_at = to_ticks(2.0)
    bad = {"present": 2.0, "past": 1.8, "nan": float("nan")}[announced]

    def update_schedule(self, now, announced=None):
        # the value the master has read (at an output point in the recorder's batch, else
        # by its own get) is replaced by the faulty announcement at t = 2 s
        if self.name == "controller" and now == fault_at:
            announced = bad
        return real_update(self, now, announced)

    monkeypatch.setattr(master_mod.FmuUnit, "update_schedule", update_schedule)
    # the fault is injected into the Python loop (the C loop's own: tests/third_party/
    # test_native_loop.py, an FMU announcing a time not in the future)
    monkeypatch.setenv(native_loop.ENV, "off")
    with pytest.raises(SimulationError) as err:
        run_scenario(PID, build=False, out_dir=tmp_path, plot=False)
    says = str(err.value)
    assert says.startswith(f"controller: next_event_time = {bad!r} s is not after the current "
                           "time 2.0 s")
    assert "partial results up to t = 2 s" in says
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["completed"] is False and "next_event_time" in summary["error"]
    assert pd.read_csv(tmp_path / "results.csv")["time"].iloc[-1] == pytest.approx(2.0)
    assert np.isfinite(summary["final_position_m"])
