"""Our master with FMI 3.0 Scheduled Execution FMUs (FMI 3.0 chap. 5): the test FMU Tasks3
(fmi3_scheduled.c: a constant, a fixed, a countdown and a triggered input clock with
priorities, an output clock) and the Modelica Reference FMU Clocks, against their partitions'
analytic activation times and the Clocks model's documented ticks; mixed with FMI 3 and FMI 2
co-simulation FMUs in one scenario run by the CLI."""

from __future__ import annotations

import math
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from test_master_third_party import write_scenario

from cosim.run.master import SimulationError
from cosim.run.master.core import Master
from cosim.run.scenario import ScenarioError, load_scenario

EPS = np.finfo(float).eps
PRIORITY = {"slow": 0, "fast": 1, "alarm": 2, "kick": 3}  # Tasks3's clocks' priority attribute


def run(sc: Path) -> tuple[Master, pd.DataFrame]:
    master = Master(load_scenario(sc))
    return master, master.run().frame


def activations(master: Master, name: str) -> list[tuple[str, float]]:
    """(clock, activation time s) as the FMU ``name`` logged them ("activate <clock> at <t>")."""
    out = []
    for message in master.by_name[name].messages:
        clock, _, time = message.removeprefix("activate ").partition(" at ")
        out.append((clock, float(time)))
    return out


def assert_activations(got: list[tuple[str, float]], expected: list[tuple[str, float]]) -> None:
    """Same partitions in the same order, at the same times within the rounding of a tick time
    shift + k interval computed in doubles (a few ulp)."""
    assert [c for c, _ in got] == [c for c, _ in expected], (got, expected)
    for (clock, t), (_, t_exact) in zip(got, expected):
        assert math.isclose(t, t_exact, rel_tol=8 * EPS, abs_tol=8 * EPS), (clock, t, t_exact)


def tasks_schedule(stop: float, slow_interval: float, alarm_at: float,
                   kicks: list[float] = ()) -> list[tuple[str, float]]:
    """Tasks3's activations up to ``stop`` (slow_shift 0): fast every 0.1 s, slow every
    ``slow_interval``, alarm once at ``alarm_at``, kick at ``kicks``; simultaneous ones in
    priority order (the alarm set by fast at the same time comes after it by its priority)."""
    n_fast = round(stop / 0.1)
    n_slow = round(stop / slow_interval)
    events = ([("fast", k / 10) for k in range(n_fast + 1)]
              + [("slow", k * slow_interval) for k in range(n_slow + 1)]
              + [("alarm", alarm_at)] + [("kick", t) for t in kicks])
    return sorted(events, key=lambda e: (round(e[1], 9), PRIORITY[e[0]]))


@pytest.mark.parametrize("slow_interval, alarm_delay", [(0.25, 0.05), (0.2, 0.0)])
def test_partitions_run_at_their_clocks_in_priority_order(c_fmus3, tmp_path, slow_interval,
                                                          alarm_delay):
    """fast (constant 0.1 s), slow (fixed: interval asked of the FMU), alarm (countdown set by
    fast's 5th activation at 0.4 s: alarm_delay later; 0: at 0.4 s after fast); simultaneous
    activations in priority order (slow before fast before alarm)."""
    sc = write_scenario(tmp_path, {"t": (c_fmus3["Tasks3"], {
        "slow_interval": slow_interval, "alarm_delay": alarm_delay}, {"u": 0.5})}, stop=1.0)
    master, frame = run(sc)
    expected = tasks_schedule(1.0, slow_interval, 0.4 + alarm_delay)
    assert_activations(activations(master, "t"), expected)
    last = frame.iloc[-1]
    assert (last["t.n_fast"], last["t.n_slow"], last["t.n_alarm"]) == (
        11, round(1.0 / slow_interval) + 1, 1)
    assert last["t.y"] == 11 * 0.5  # y += u at every fast activation (u = 0.5: exact sums)
    assert math.isclose(last["t.t_alarm"], 0.4 + alarm_delay, rel_tol=8 * EPS)


def test_an_output_clock_triggers_another_fmus_partition(c_fmus3, tmp_path):
    """a.done ticks at every slow activation of a: b's triggered clock kick runs then, after
    b's own partitions due at that time (kick has the lowest priority)."""
    fmu = c_fmus3["Tasks3"]
    sc = write_scenario(tmp_path, {"a": (fmu, {}, {}), "b": (fmu, {}, {})},
                        connections={"b.kick": "a.done"}, stop=1.0)
    master, frame = run(sc)
    slow = [k * 0.25 for k in range(5)]
    assert_activations(activations(master, "b"), tasks_schedule(1.0, 0.25, 0.45, slow))
    assert_activations(activations(master, "a"), tasks_schedule(1.0, 0.25, 0.45))
    assert frame["b.n_kick"].iloc[-1] == 5 and frame["b.t_kick"].iloc[-1] == 1.0


def test_a_co_simulation_output_clock_triggers_a_partition(c_fmus3, tmp_path):
    """Ticker3 (co-simulation, Event Mode: an event every 0.1 s from 0.1 s, its output clock
    ticked active at each) -> Tasks3's triggered clock kick: kick runs at every Ticker3 event,
    after Tasks3's own partitions due then (kick has the lowest priority); Ticker3 also runs
    as before (n = 10 events by 1 s)."""
    sc = write_scenario(tmp_path, {"ticker": (c_fmus3["Ticker3"], {"period": 0.1}, {}),
                                   "b": (c_fmus3["Tasks3"], {}, {})},
                        connections={"b.kick": "ticker.ticked"}, stop=1.0)
    master, frame = run(sc)
    kicks = [k / 10 for k in range(1, 11)]
    assert_activations(activations(master, "b"), tasks_schedule(1.0, 0.25, 0.45, kicks))
    last = frame.iloc[-1]
    assert (last["b.n_kick"], last["ticker.n"]) == (10, 10)
    assert math.isclose(last["b.t_kick"], 1.0, rel_tol=8 * EPS)


def test_clock_connections_are_checked(c_fmus3, c_fmus, tmp_path):
    fmu = c_fmus3["Tasks3"]
    sc = write_scenario(tmp_path, {"a": (fmu, {}, {}), "b": (fmu, {}, {})},
                        connections={"b.alarm": "a.done"})
    with pytest.raises(ScenarioError, match=r"\[connections\] \"b.alarm\" = \"a.done\": "
                                            r"b.alarm has intervalVariability 'countdown'"):
        run(sc)
    sc = write_scenario(tmp_path, {"a": (fmu, {}, {}), "b": (fmu, {}, {})},
                        connections={"b.kick": "a.fast"})
    with pytest.raises(ScenarioError, match=r"a.fast is not an output Clock"):
        run(sc)
    sc = write_scenario(tmp_path, {"a": (fmu, {}, {}), "cd": (c_fmus3["Countdown3"], {}, {})},
                        connections={"a.kick": "cd.tick"})
    with pytest.raises(ScenarioError, match=r"cd.tick is not an output Clock"):
        run(sc)
    sc = write_scenario(tmp_path, {"a": (fmu, {}, {}), "cd": (c_fmus3["Countdown3"], {}, {})},
                        connections={"cd.tick": "a.done"})
    # a co-simulation FMU's input clock may be triggered by another's output clock (FMI 3.0
    # sec. 2.2.8.2), a countdown one may not
    with pytest.raises(ScenarioError, match=r"\[connections\] \"cd.tick\" = \"a.done\": cd.tick "
                                            r"has intervalVariability 'countdown'"):
        run(sc)


def test_an_input_clock_without_priority_is_refused(c_fmus3, tmp_path):
    """FMI 3.0 sec. 2.4.4: an input clock of a Scheduled Execution FMU declares a priority;
    Tasks3 with the alarm clock's removed."""
    fmu = tmp_path / "NoPriority.fmu"
    with zipfile.ZipFile(c_fmus3["Tasks3"]) as source, zipfile.ZipFile(fmu, "w") as out:
        for item in source.infolist():
            data = source.read(item)
            if item.filename == "modelDescription.xml":
                assert b'priority="2"' in data
                data = data.replace(b'priority="2"', b"")
            out.writestr(item, data)
    sc = write_scenario(tmp_path, {"t": (fmu, {}, {})})
    with pytest.raises(SimulationError, match=r"NoPriority.fmu: modelDescription.xml: input "
                                              r"Clock 'alarm' has no priority"):
        run(sc)


def test_a_changing_clock_activates_its_partition_where_the_fmu_says(c_fmus3, tmp_path):
    """TasksChanging3: slow is a changing clock (FMI 3.0 sec. 2.2.8.2), its first interval
    0.25 s asked in Initialization Mode, each next one asked right after its activation,
    doubled: activations at 0.25, 0.75 and 1.75 s (t_i = t_(i-1) + T_interval,i)."""
    sc = write_scenario(tmp_path, {"t": (c_fmus3["TasksChanging3"], {}, {})}, stop=2.0)
    master, frame = run(sc)
    assert [a for a in activations(master, "t") if a[0] == "slow"] == [
        ("slow", 0.25), ("slow", 0.75), ("slow", 1.75)]
    assert master.by_name["t"].activations.count(("slow", 0.75)) == 1
    assert frame["t.n_slow"].iloc[-1] == 3


def test_a_fixed_step_algorithm_refuses_a_scheduled_execution_fmu(c_fmus3, tmp_path):
    sc = write_scenario(tmp_path, {"t": (c_fmus3["Tasks3"], {}, {})}, algorithm="fixed")
    with pytest.raises(SimulationError, match=r'Scheduled Execution.*algorithm = "event"'):
        run(sc)


def test_reference_clocks_ticks_as_documented(reference_clocks, tmp_path):
    """The Reference FMU Clocks (its modelDescription's table): inClock1 every second, the
    countdown inClock3 once at 4 s (set to 0 by inClock1's partition at 4 s: after it, by
    priority); totalInClockTicks counts every activation; no trigger for inClock2: it never
    ticks."""
    sc = write_scenario(tmp_path, {"c": (reference_clocks, {}, {})}, stop=10.0, output=1.0)
    master, frame = run(sc)
    t = frame["time"].to_numpy()
    np.testing.assert_array_equal(t, np.arange(11.0))
    np.testing.assert_array_equal(frame["c.inClock1Ticks"], t + 1)
    np.testing.assert_array_equal(frame["c.inClock3Ticks"], t >= 4)
    np.testing.assert_array_equal(frame["c.output3"], 1000 * (t >= 4))
    np.testing.assert_array_equal(frame["c.inClock2Ticks"], 0)
    np.testing.assert_array_equal(frame["c.totalInClockTicks"], t + 1 + (t >= 4))
    assert master.by_name["c"].activations == sorted(
        [("inClock1", float(k)) for k in range(11)] + [("inClock3", 4.0)],
        key=lambda a: (a[1], a[0]))


def test_cosim_run_gives_the_reference_clocks_documented_tick_table(reference_clocks, c_fmus3,
                                                                    tmp_path):
    """`cosim run` on the Reference FMU Clocks with its inClock2 wired to Pulses3's output
    clock (a co-simulation FMU whose events are at 0, 1, 8 and 9 s): the tick table of its
    modelDescription, inClock1 every second, inClock2 at 0, 1, 8 and 9 s, the countdown
    inClock3 at 4 s, in results.csv after each second's activations (up to 10 s)."""
    sc = write_scenario(tmp_path, {"c": (reference_clocks, {}, {}),
                                   "p": (c_fmus3["Pulses3"], {}, {})},
                        connections={"c.inClock2": "p.ticked"}, stop=10.0, output=1.0)
    done = subprocess.run([sys.executable, "-m", "cosim.cli", "run", str(sc), "--quiet",
                           "--no-plot", "--out", str(tmp_path / "out")],
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    frame = pd.read_csv(tmp_path / "out" / "results.csv")
    t = frame["time"].to_numpy()
    np.testing.assert_array_equal(t, np.arange(11.0))
    in1 = t + 1
    in2 = np.array([sum(s <= k for s in (0, 1, 8, 9)) for k in t])
    in3 = (t >= 4).astype(int)
    np.testing.assert_array_equal(frame["c.inClock1Ticks"], in1)
    np.testing.assert_array_equal(frame["c.inClock2Ticks"], in2)
    np.testing.assert_array_equal(frame["c.inClock3Ticks"], in3)
    np.testing.assert_array_equal(frame["c.totalInClockTicks"], in1 + in2 + in3)
    np.testing.assert_array_equal(frame["p.n"], in2)


def test_reference_clocks_with_its_triggered_clocks_wired(reference_clocks, c_fmus3, tmp_path):
    """Clocks' outClock ticks when totalInClockTicks reaches a multiple of 5 (at 4 s and 8 s
    with inClock1 and inClock3 alone): it triggers Tasks3's kick there. With inClock2 triggered
    by a Tasks3's done (slow every 2 s) and input2 = its n_fast (10 t + 1 after its fast
    partition at t), result2 sums input2 over inClock2's ticks 0, 2, ..., 10 s."""
    sc = write_scenario(tmp_path, {"c": (reference_clocks, {}, {}),
                                   "k": (c_fmus3["Tasks3"], {}, {})},
                        connections={"k.kick": "c.outClock"}, stop=10.0, output=1.0)
    master, frame = run(sc)
    assert [a for a in master.by_name["k"].activations if a[0] == "kick"] == [
        ("kick", 4.0), ("kick", 8.0)]
    sc = write_scenario(tmp_path, {"c": (reference_clocks, {}, {}),
                                   "s": (c_fmus3["Tasks3"], {"slow_interval": 2.0}, {})},
                        connections={"c.inClock2": "s.done", "c.input2": "s.n_fast"},
                        stop=10.0, output=1.0)
    master, frame = run(sc)
    ticks = [2.0 * k for k in range(6)]
    assert [a for a in master.by_name["c"].activations if a[0] == "inClock2"] == [
        ("inClock2", t) for t in ticks]
    at_4 = [a[0] for a in master.by_name["c"].activations if a[1] == 4.0]
    assert at_4 == ["inClock1", "inClock2", "inClock3"]  # priorities 0, 1, 2
    assert frame["c.inClock2Ticks"].iloc[-1] == 6
    assert frame["c.result2"].iloc[-1] == sum(10 * t + 1 for t in ticks)


def test_cli_runs_scheduled_execution_with_fmi3_and_fmi2_co_simulation(c_fmus, c_fmus3,
                                                                       tmp_path):
    """FMI 2 Feedthrough (z = 0.5 t) -> Tasks3 (SE: y += u at every fast tick, k/10 s) ->
    FMI 3 TimeEvents3 (CS: q = u at its events, every 0.1 s): q equals y at every output
    point, and y = sum over the fast ticks so far of 0.5 k/10."""
    sc = write_scenario(tmp_path, {
        "plant": (c_fmus["Feedthrough"], {"k": 1.0}, {"u": 0.5}),
        "task": (c_fmus3["Tasks3"], {}, {}),
        "sampler": (c_fmus3["TimeEvents3"], {"period": 0.1}, {})},
        connections={"task.u": "plant.z", "sampler.u": "task.y"}, stop=1.0)
    done = subprocess.run([sys.executable, "-m", "cosim.cli", "run", str(sc), "--quiet",
                           "--no-plot", "--out", str(tmp_path / "out")],
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    frame = pd.read_csv(tmp_path / "out" / "results.csv")
    np.testing.assert_array_equal(frame["sampler.q"], frame["task.y"])
    fast = np.floor(frame["time"].to_numpy() * 10 + 1e-9)  # index of the last fast tick
    exact = 0.5 * 0.1 * fast * (fast + 1) / 2
    # z integrates u in doSteps of up to 0.125 s: each term within a few ulp of 0.5 t
    np.testing.assert_allclose(frame["task.y"], exact, rtol=64 * EPS, atol=64 * EPS)
