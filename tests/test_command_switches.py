"""command_switches counts changes larger than a stated resolution (issue 12: seed 004 counted
800 switches of a command that was flat but for solver noise)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest

from cosim.run.metrics import COMMAND_RESOLUTION_REL, command_switches, compute_summary

RNG = np.random.default_rng(12)


def _flat_noisy(level: float, noise: float, n: int = 800) -> np.ndarray:
    return level + noise * RNG.standard_normal(n)


def _square(n_periods: int, low: float, high: float, width: int = 20) -> np.ndarray:
    return np.tile(np.r_[np.full(width, low), np.full(width, high)], n_periods)


def test_flat_but_noisy_command_has_no_switches():
    """8 kN held, noise 1e-4 N (seed 004's cruise): every sample differs, none is a switch."""
    u = _flat_noisy(8066.0, 1e-4)
    assert np.count_nonzero(np.diff(u)) == u.size - 1  # the old count: 799
    count, res = command_switches(u)
    assert count == 0
    assert res == pytest.approx(COMMAND_RESOLUTION_REL * np.max(np.abs(u)))


def test_real_switching_command_counts_every_switch():
    """A square wave 0 <-> 80 kN, 10 periods: 19 switches, with or without noise on it."""
    u = _square(10, 0.0, 80e3)
    assert command_switches(u)[0] == 19
    assert command_switches(u + 1e-4 * RNG.standard_normal(u.size))[0] == 19


def test_stated_resolution_is_used():
    """Steps of 5 between levels: counted at resolution 4, not at 6 (the user's resolution)."""
    u = np.repeat([0.0, 5.0, 10.0, 5.0], 3)
    assert command_switches(u, 4.0) == (3, 4.0)
    assert command_switches(u, 6.0) == (0, 6.0)
    assert command_switches(np.zeros(5)) == (0, 0.0)
    assert command_switches([1.0]) == (0, COMMAND_RESOLUTION_REL)


def _result(frame: pd.DataFrame, summary: dict, connection_values: dict | None = None):
    return SimpleNamespace(scenario=SimpleNamespace(name="stub", summary=summary), frame=frame,
                           algorithm="event", sim_time_s=1.0, wall_time_s=1.0, completed=True,
                           error=None, connection_values=connection_values or {},
                           executions={}, do_steps={}, fmu_wall_time_s={}, final_outputs={})


def test_summary_of_a_recorded_command_states_its_resolution():
    u = _flat_noisy(4677.0, 1e-4, 50)
    frame = pd.DataFrame({"time": np.arange(50.0), "controller.force_demand": u})
    s = compute_summary(_result(frame, {"command": "controller.force_demand"}))
    assert s["command_switches"] == 0
    assert s["command_switch_resolution"] == pytest.approx(1e-6 * np.max(np.abs(u)))
    s = compute_summary(_result(frame, {"command": "controller.force_demand",
                                        "command_resolution": 1e-9}))
    assert s["command_switches"] == 49 and s["command_switch_resolution"] == 1e-9


def test_summary_prefers_the_values_passed_on_over_the_recording():
    """A connected command is counted from every value the master passed on (events between
    output points included), not from the coarser recording."""
    frame = pd.DataFrame({"time": [0.0, 1.0], "controller.u": [0.0, 0.0]})
    s = compute_summary(_result(frame, {"command": "controller.u"},
                                {"controller.u": [0.0, 50.0, 0.0]}))
    assert s["command_switches"] == 2


def test_run_counts_the_values_the_plant_received(built_fmus):
    """seed 000 PID: the summary's count is that of the command values the plant was given
    (recorded here at every event: output interval = sample time), at the resolution asked."""
    from cosim.run.simulate import run_scenario

    r = run_scenario("seed000_stop_pid", ["summary.command_resolution=0.5"], build=False,
                     plot=False)
    passed = r.connection_values["controller.brake_command"]
    recorded = r.frame["controller.brake_command"].to_numpy()
    steps = np.abs(np.diff(recorded))
    assert r.summary["command_switches"] == np.count_nonzero(steps > 0.5)
    assert 0 < r.summary["command_switches"] < np.count_nonzero(steps > 0.0)
    assert len(passed) == 1 + np.count_nonzero(steps > 0.0)
