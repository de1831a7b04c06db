"""Master: event scheduling, event-driven == fixed-step, Jacobi delay, scenario errors."""

from __future__ import annotations

import fmpy
import numpy as np
import pytest

from cosim.run.master import native_loop
from cosim.run.scenario import ScenarioError, load_scenario
from cosim.run.simulate import run_scenario

PID = "seed000_stop_pid"


@pytest.fixture(scope="module")
def event_run(built_fmus):
    return run_scenario(PID, build=False)


def _max_diff(a, b) -> float:
    fa, fb = a.frame.set_index("time"), b.frame.set_index("time")
    common = fa.index.intersection(fb.index)
    assert len(common) == len(fa)
    return float(np.max(np.abs(fa.loc[common].to_numpy() - fb.loc[common].to_numpy())))


@pytest.mark.parametrize("base_step", [0.2, 0.01, 0.05])
def test_event_driven_equals_fixed_step(event_run, base_step):
    fixed = run_scenario(PID, algorithm="fixed", build=False,
                         overrides={"simulation.base_step": base_step})
    assert _max_diff(event_run, fixed) < 1e-9
    assert fixed.summary["stop_error_m"] == pytest.approx(event_run.summary["stop_error_m"],
                                                          abs=1e-9)
    # the fixed-step master steps the controller every base step, it computes only at events
    assert fixed.do_steps["controller"] == round(60.0 / base_step)
    assert fixed.executions["controller"] == event_run.executions["controller"]


def test_event_schedule_counts(event_run):
    s = event_run.summary
    # controller: one event per 0.2 s sample, t = 0 .. 60 s inclusive; stepped once per event
    assert s["executions"]["controller"] == 301
    assert s["do_steps"]["controller"] == 300
    # plant: one doStep per communication point (sample times and output points coincide)
    assert s["do_steps"]["plant"] == 300
    assert s["sim_time_s"] == pytest.approx(60.0)


def test_controller_sampling_independent_of_output_interval(event_run):
    """A finer output grid adds plant steps but neither controller events nor changes."""
    fine = run_scenario(PID, build=False, overrides={"simulation.output_interval": 0.05})
    assert fine.executions["controller"] == 301
    assert fine.do_steps["controller"] == 300
    assert fine.do_steps["plant"] == 1200
    assert _max_diff(event_run, fine) < 1e-9


def test_pid_stops_inside_window(event_run):
    s = event_run.summary
    # 14.9 cm (paper: 28.98 cm). No iterative solver in the loop: only rounding differences
    # between platforms can move it, far below 1 mm, which still catches any regression
    assert s["stop_error_m"] == pytest.approx(0.14949, abs=1e-3)
    assert s["final_speed_mps"] == 0.0
    assert s["command_switches"] > 0


def _with_inputs_recorded(algorithm: str):
    sc = load_scenario(PID)
    sc.record = [*sc.record, "plant.brake_command", "controller.speed_error"]
    return run_scenario(sc, algorithm=algorithm, build=False, plot=False)


@pytest.mark.parametrize("algorithm, delay", [("jacobi", 1), ("event", 0), ("fixed", 0)])
def test_jacobi_delays_command_by_one_step(built_fmus, algorithm, delay):
    """Jacobi (all outputs read, then all inputs set, as libcosim): the controller's event at
    t_k computes from the plant outputs of t_(k-1), and the plant is recorded at t_k with the
    command of t_(k-1) (the next one is set after the recording). Gauss-Seidel (event, fixed):
    both from t_k. Checked on every sample against the PID's error law
    ``e = v - sqrt(2 a0 (s_stop - s))`` evaluated here on the recorded plant outputs."""
    from cosim.fmu.profiles import StoppingCurve

    f = _with_inputs_recorded(algorithm).frame
    assert np.allclose(np.diff(f["time"]), 0.2, rtol=0, atol=1e-12)  # one row per event
    curve = StoppingCurve(0.5, 400.0)
    v, s = f["plant.v"].to_numpy(), f["plant.s"].to_numpy()
    error = f["controller.speed_error"].to_numpy()
    measured = np.arange(1, len(f)) - delay
    assert list(error[1:]) == [v[k] - curve.speed(s[k]) for k in measured]
    assert error[0] == v[0] - curve.speed(s[0])  # initial values flow in initialization
    command = f["controller.brake_command"].to_numpy()
    applied = f["plant.brake_command"].to_numpy()
    assert list(applied[1:]) == list(command[1 - delay:len(f) - delay])
    assert np.count_nonzero(np.diff(command)) > 100  # a changing command: the check can fail


def test_sample_time_override_changes_schedule(built_fmus):
    r = run_scenario(PID, build=False, overrides={"controller.sample_time": 0.4,
                                                  "simulation.stop_time": 10.0})
    assert r.executions["controller"] == 26  # t = 0, 0.4, ..., 10.0
    assert r.do_steps["controller"] == 25


def _variant(tmp_path, old: str, new: str):
    text = load_scenario(PID).path.read_text()
    assert old in text
    path = tmp_path / "variant.toml"
    path.write_text(text.replace(old, new))
    return path


@pytest.mark.parametrize("old,new,message", [
    ('fmu = "StopPid"', 'fmu = "StopPID"', "unknown FMU.*did you mean 'StopPid'"),
    ("mass = 490000.0", "mas = 490000.0", "no variable 'mas'.*did you mean 'mass'"),
    ("mass = 490000.0", 'mass = "heavy"', "mass is Real, got 'heavy'"),
    ('"controller.s" = "plant.s"', '"controller.s" = "plant.v"', "unit mismatch"),
    ("output_interval = 0.2", "output_interval = -0.2", "output_interval = -0.2: must be pos"),
    ("base_step = 0.2", "base_step = 0", "base_step = 0.0: must be positive"),
    ('"plant.brake_command" = "controller.brake_command"',
     '"plant.brake_command" = "controller.executions"', "type mismatch"),
    ("brake_delay = 1.0", "brake_delay = -1.0", "brake_delay = -1.0: must be at least 0.0"),
    ('algorithm = "event"', 'algorithm = "gauss"', "algorithm = 'gauss'"),
    ('"controller.v" = "plant.v"', '"controller.v" = "plant.speed"', "no variable 'speed'"),
])
def test_scenario_errors_name_file_key_and_problem(tmp_path, built_fmus, old, new, message):
    path = _variant(tmp_path, old, new)
    with pytest.raises(ScenarioError, match=message) as info:
        run_scenario(path, build=False)
    assert str(path) in str(info.value)


def test_an_unconnected_input_keeps_its_start_value_unless_the_scenario_says_error(
        tmp_path, built_fmus, caplog):
    """Without "controller.s" = "plant.s" the controller reads its declared start value of s
    (one log line names it); with [simulation] unconnected_inputs = "error" the run is
    refused, naming the file and the key."""
    path = _variant(tmp_path, '"controller.s" = "plant.s"\n', "")
    with pytest.raises(ScenarioError, match=r"input controller.s is not connected \(\[simulati"
                                            r"on\] unconnected_inputs = \"error\"\)") as info:
        run_scenario(path, build=False, overrides=["simulation.unconnected_inputs=error"])
    assert str(path) in str(info.value)
    with pytest.raises(ScenarioError, match=r"unconnected_inputs = 'strict': expected one of"):
        load_scenario(path, ["simulation.unconnected_inputs=strict"])
    with caplog.at_level("WARNING", logger="cosim.run.master.core"):
        r = run_scenario(path, build=False, overrides=["simulation.stop_time=1.0"])
    kept = [rec.getMessage() for rec in caplog.records if "keep their start" in rec.getMessage()]
    start = next(v.start for v in fmpy.read_model_description(
        str(r.scenario.components["controller"].fmu_path)).modelVariables if v.name == "s")
    assert kept == [f"{path}: inputs neither connected nor set keep their start values: "
                    f"controller.s = {start}"]
    assert r.completed


def test_bad_override_is_reported(built_fmus):
    with pytest.raises(ScenarioError, match="no FMU named 'plnt'"):
        load_scenario(PID, ["plnt.mass=1"])
    with pytest.raises(ScenarioError, match="expected KEY=VALUE"):
        load_scenario(PID, ["plant.mass"])


def test_override_sets_parameter(built_fmus):
    """--set values reach the FMU: it reports them (parameters read back through getReal on
    every recorded row) and acts on them (a 0.4 s dead time: the first command, computed at
    t = 0, is applied from 0.4 s instead of the scenario's 1.0 s)."""
    sc = load_scenario(PID, ["plant.brake_gain=0.009", "plant.brake_delay=0.4",
                             "simulation.stop_time=20"])
    sc.record = [*sc.record, "plant.brake_gain", "plant.brake_delay"]
    heavy = run_scenario(sc, build=False, plot=False)
    f = heavy.frame
    assert set(f["plant.brake_gain"]) == {0.009} and set(f["plant.brake_delay"]) == {0.4}
    applied = f.set_index(f["time"].round(6))["plant.applied_command"]
    first = f["controller.brake_command"].iloc[0]
    assert first > 0.0
    assert applied.loc[0.2] == 0.0 and applied.loc[0.4] == first
    assert heavy.sim_time_s == pytest.approx(20.0)


def test_invalid_toml_reported(tmp_path):
    path = tmp_path / "broken.toml"
    path.write_text("[simulation\nstop_time = 1")
    with pytest.raises(ScenarioError, match="not valid TOML"):
        load_scenario(path)


def test_failure_mid_run_keeps_partial_results(built_fmus, tmp_path, monkeypatch):
    """An FMU failing at t = 10 s: the error names it, and what was recorded is written."""
    import json

    import pandas as pd

    from cosim.run import master as master_mod

    real_step = master_mod.FmuUnit.step_to

    def failing_step(self, ticks):
        if self.name == "plant" and ticks > 10_000_000_000:
            raise master_mod.SimulationError("plant: doStep at t=10 s failed: test fault")
        return real_step(self, ticks)

    monkeypatch.setattr(master_mod.FmuUnit, "step_to", failing_step)
    monkeypatch.setenv(native_loop.ENV, "off")  # the fault is injected into the Python loop
    with pytest.raises(master_mod.SimulationError, match="test fault.*partial results up to"):
        run_scenario(PID, build=False, out_dir=tmp_path)
    frame = pd.read_csv(tmp_path / "results.csv")
    assert frame["time"].iloc[-1] == pytest.approx(10.0)
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["completed"] is False and "test fault" in summary["error"]
    assert summary["sim_time_s"] == pytest.approx(10.0)
    assert (tmp_path / "plot.png").exists()


def test_a_recording_larger_than_memory_is_refused_before_the_run(built_fmus, monkeypatch):
    """stop_time = 1e9 s at 0.2 s: 5e9 output points would not fit; the run is refused
    before any step, saying how much the recording needs (points x values x 8 bytes)."""
    from cosim.run.master import SimulationError
    from cosim.run.master import observers as master_module
    from cosim.run.simulate import run_scenario

    steps: list[float] = []
    with pytest.raises(SimulationError, match=r"the recording needs \d.* GiB \(5000000002 output "
                                              r"points x \d+ values x 8 bytes"):
        run_scenario("seed000_stop_pid", overrides=["simulation.stop_time=1e9"],
                     progress=lambda t, total: steps.append(t))
    assert not steps
    # the same bound for a small run when memory is short: 302 points x 8 values x 8 bytes
    monkeypatch.setattr(master_module, "available_memory", lambda: 3 * 302 * 8 * 8 - 1)
    with pytest.raises(SimulationError, match=r"302 output points x 8 values"):
        run_scenario("seed000_stop_pid", overrides=["simulation.stop_time=60"])
    monkeypatch.setattr(master_module, "available_memory", lambda: 3 * 302 * 8 * 8)
    assert run_scenario("seed000_stop_pid", overrides=["simulation.stop_time=60"]).completed
