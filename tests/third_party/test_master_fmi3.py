"""Our master with third-party FMI 3.0 co-simulation FMUs (plain C, fmi3_models.c): every
type and an array through a Feedthrough (equal to ``fmpy.simulate_fmu``), an FMU ending the run
with terminateSimulation (equal to fmpy), announced time events (nextEventTime) and early
return, a countdown clock (analytic oracles: fmpy schedules neither), FMI 2 and FMI 3 FMUs in
one scenario."""

from __future__ import annotations

import math
import zipfile
from fractions import Fraction

import numpy as np
import pytest
from fmpy import simulate_fmu
from test_master_third_party import H, write_scenario

from cosim.run.master import SimulationError
from cosim.run.simulate import run_scenario

VALUES = {"Float64": 0.1, "Float32": 0.25, "Int8": -100, "UInt8": 200, "Int16": -30000,
          "UInt16": 60000, "Int32": -2**31, "UInt32": 2**32 - 1, "Int64": -2**40,
          "UInt64": 2**40, "Boolean": True, "String": "hello", "Binary": "00ff10",
          "Enumeration": "fast"}


def test_feedthrough_of_every_type_and_an_array_equals_fmpy(c_fmus3, tmp_path):
    fmu = c_fmus3["Feedthrough3"]
    inputs = {f"u_{k}": v for k, v in VALUES.items()}
    inputs.update({f"\"ua[{i}]\"": float(i) for i in (1, 2, 3)})
    numeric = [k for k in VALUES if k not in ("String", "Binary")]
    record = [f"ft.y_{k}" for k in numeric] + ["ft.ya[*]", "ft.y_String", "ft.y_Binary"]
    sc = write_scenario(tmp_path, {"ft": (fmu, {}, inputs)}, stop=0.5, record=record)
    r = run_scenario(sc, build=False)
    f = r.frame
    for kind in numeric:
        expected = {"Float32": np.float32(0.25), "Boolean": 1.0, "Enumeration": 3.0}.get(
            kind, VALUES[kind])
        assert (f[f"ft.y_{kind}"] == float(expected)).all(), kind
    assert list(f[["ft.ya[1]", "ft.ya[2]", "ft.ya[3]"]].iloc[-1]) == [1.0, 2.0, 3.0]
    assert set(f["ft.y_String"]) == {"hello"}
    assert set(f["ft.y_Binary"]) == {"00ff10"}  # as scenarios write Binary: hexadecimal
    start = {f"u_{k}": v for k, v in VALUES.items()
             if k not in ("String", "Binary", "Enumeration")}
    ref = simulate_fmu(str(fmu), stop_time=0.5, output_interval=H, start_values=start,
                       output=[f"y_{k}" for k in numeric if k != "Enumeration"])
    np.testing.assert_array_equal(f["time"].to_numpy(), ref["time"])
    for kind in numeric:
        if kind != "Enumeration":
            np.testing.assert_array_equal(f[f"ft.y_{kind}"].to_numpy(dtype=float),
                                          ref[f"y_{kind}"].astype(float), err_msg=kind)


def test_an_out_of_range_value_names_the_key(c_fmus3, tmp_path):
    from cosim.run.scenario import ScenarioError

    sc = write_scenario(tmp_path, {"ft": (c_fmus3["Feedthrough3"], {}, {"u_UInt8": 256})})
    with pytest.raises(ScenarioError, match=r"\[fmus.ft.inputs\] u_UInt8.*range of UInt8"):
        run_scenario(sc, build=False)


@pytest.mark.parametrize("algorithm", ["event", "fixed"])
def test_terminate_simulation_ends_the_run_like_fmpy(c_fmus3, tmp_path, algorithm):
    fmu = c_fmus3["Terminator3"]
    sc = write_scenario(tmp_path, {"term": (fmu, {"stop_at": 0.625}, {})}, algorithm=algorithm)
    r = run_scenario(sc, build=False)
    assert r.terminated_by == {"instance": "term", "time": 0.625}
    ref = simulate_fmu(str(fmu), stop_time=1.0, output_interval=H,
                       start_values={"stop_at": 0.625}, output=["x"])
    _, first = np.unique(ref["time"], return_index=True)
    np.testing.assert_array_equal(r.frame["time"].to_numpy(), ref["time"][first])
    np.testing.assert_array_equal(r.frame["term.x"].to_numpy(), ref["x"][first])


@pytest.mark.parametrize("announce", [True, False])
def test_announced_events_and_early_return_are_communication_points(c_fmus3, tmp_path,
                                                                    announce):
    """period 0.3 s on a 0.125 s output grid: each event k 0.3 s becomes a communication point
    (announced as nextEventTime, or by an early return from doStep), where the FMU samples its
    input u = the time from the Terminator3 (x = t): q jumps to exactly k 0.3."""
    sc = write_scenario(tmp_path, {
        "ev": (c_fmus3["TimeEvents3"], {"period": 0.3, "announce": announce}, {}),
        "clock": (c_fmus3["Terminator3"], {"stop_at": 10.0}, {})},
        connections={"ev.u": "clock.x"}, stop=1.0)
    r = run_scenario(sc, build=False)
    f = r.frame
    times = f["time"].to_numpy()
    n = np.floor(times / 0.3 + 1e-9)
    np.testing.assert_array_equal(f["ev.n"].to_numpy(), n)
    np.testing.assert_allclose(f["ev.q"].to_numpy(), n * 0.3, rtol=0, atol=1e-15)
    # one extra communication point per event (0.3, 0.6, 0.9) besides the 9 output points
    assert r.do_steps["clock"] == 8 + 3


def _countdown_run(c_fmus3, tmp_path, parameters: dict) -> tuple[np.ndarray, ...]:
    """(times, n, q) of Countdown3 with ``parameters``, its input u the time (Terminator3's
    x), so q is the time of its last tick."""
    sc = write_scenario(tmp_path, {
        "cd": (c_fmus3["Countdown3"], parameters, {}),
        "clock": (c_fmus3["Terminator3"], {"stop_at": 10.0}, {})},
        connections={"cd.u": "clock.x"}, stop=2.0)
    f = run_scenario(sc, build=False).frame
    return f["time"].to_numpy(), f["cd.n"].to_numpy(), f["cd.q"].to_numpy()


def test_countdown_clock_ticks_at_the_intervals_the_fmu_gives(c_fmus3, tmp_path):
    """first 0.1 s, told by the FMU in Initialization Mode only (FMI 3.0 sec. 2.2.8.2: the
    importer asks a countdown clock's interval there; t_0 = t_start + T_interval,0), then
    doubling, told in Event Mode: ticks at 0.1, 0.3, 0.7, 1.5 s (sums of 0.1 2^k); q is the
    time at the last tick (sums of doubles 0.1 2^k, within 2 ulp of 1.5)."""
    times, n_ticks, q = _countdown_run(c_fmus3, tmp_path, {"first": 0.1})
    n, last = _last_tick(times, np.array([0.1, 0.3, 0.7, 1.5]))
    assert n[-1] == 4
    np.testing.assert_array_equal(n_ticks, n)
    np.testing.assert_allclose(q, last, rtol=0, atol=2 * np.spacing(1.5))


def test_a_countdown_clock_with_first_interval_0_ticks_at_the_start(c_fmus3, tmp_path):
    """first 0 s (T_interval,0 >= 0, FMI 3.0 sec. 2.2.8.2): a tick at the start time, in the
    Event Mode after Initialization Mode; then period 0.1 s, doubling: 0, 0.1, 0.3, 0.7, 1.5 s."""
    times, n_ticks, q = _countdown_run(c_fmus3, tmp_path, {"first": 0.0, "period": 0.1})
    n, last = _last_tick(times, np.array([0.0, 0.1, 0.3, 0.7, 1.5]))
    assert n[0] == 1
    np.testing.assert_array_equal(n_ticks, n)
    np.testing.assert_allclose(q, last, rtol=0, atol=2 * np.spacing(1.5))


def test_a_countdown_clock_at_interval_0_ticks_again_at_the_same_event(c_fmus3, tmp_path):
    """repeat 2: after each tick the FMU says interval 0 twice (t_i = t_event + 0, FMI 3.0
    sec. 2.2.8.2), so the clock ticks three times at each of 0.1, 0.3, 0.7, 1.5 s (the
    master sets it and calls fmi3UpdateDiscreteStates again in the same Event Mode)."""
    times, n_ticks, q = _countdown_run(c_fmus3, tmp_path, {"first": 0.1, "repeat": 2})
    n, last = _last_tick(times, np.array([0.1, 0.3, 0.7, 1.5]))
    np.testing.assert_array_equal(n_ticks, 3 * n)
    np.testing.assert_allclose(q, last, rtol=0, atol=2 * np.spacing(1.5))


def test_a_countdown_clock_with_a_negative_first_interval_is_refused(c_fmus3, tmp_path):
    sc = write_scenario(tmp_path, {"cd": (c_fmus3["Countdown3"], {"first": -0.1}, {})})
    with pytest.raises(SimulationError, match=r"countdown clock tick: fmi3GetIntervalDecimal "
                                              r"in Initialization Mode gave -0\.1 s"):
        run_scenario(sc, build=False)


def test_clocks_need_the_event_algorithm(c_fmus3, tmp_path):
    sc = write_scenario(tmp_path, {"cd": (c_fmus3["Countdown3"], {}, {"u": 1.0})},
                        algorithm="fixed")
    with pytest.raises(SimulationError, match="input clocks \\(tick\\).*algorithm = \"event\""):
        run_scenario(sc, build=False)


def test_fmi2_and_fmi3_in_one_scenario(c_fmus, c_fmus3, tmp_path):
    """FMI 2 Feedthrough (y = k u, Real) feeding the FMI 3 Feedthrough (Float64) and back."""
    sc = write_scenario(tmp_path, {
        "f2": (c_fmus["Feedthrough"], {"k": 2.0}, {}),
        "f3": (c_fmus3["Feedthrough3"], {}, {})},
        connections={"f3.u_Float64": "f2.z", "f2.u": "f3.y_Float32"},
        record=["f2.z", "f3.y_Float64"], stop=0.5)
    # f2.u is fed by f3.y_Float32 (declared Float32: a type mismatch the checks refuse)
    from cosim.run.scenario import ScenarioError

    with pytest.raises(ScenarioError, match="type mismatch"):
        run_scenario(sc, build=False)
    sc = write_scenario(tmp_path, {
        "f2": (c_fmus["Feedthrough"], {"k": 2.0}, {"u": 0.5}),
        "f3": (c_fmus3["Feedthrough3"], {}, {
            **{f"u_{k}": v for k, v in VALUES.items() if k != "Float64"},
            **{f"\"ua[{i}]\"": 0.0 for i in (1, 2, 3)}})},
        connections={"f3.u_Float64": "f2.z"}, record=["f2.z", "f3.y_Float64"], stop=0.5)
    r = run_scenario(sc, build=False)
    np.testing.assert_array_equal(r.frame["f3.y_Float64"], r.frame["f2.z"])
    assert not math.isnan(r.frame["f2.z"].iloc[-1])


def _last_tick(times: np.ndarray, ticks: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(ticks up to each time, time of the last of them or 0) for recorded ``times``."""
    n = (times[:, None] >= ticks[None, :] - 1e-12).sum(axis=1)
    return n, np.array([ticks[k - 1] if k else 0.0 for k in n])


@pytest.mark.parametrize("announce", [True, False])
def test_event_times_that_are_not_whole_nanoseconds_are_reached_exactly(c_fmus3, tmp_path,
                                                                        announce):
    """period 1/3 s, compared exactly by the FMU (tolerance 0): it announces 1/3, 2/3, 1, 4/3
    ... as doubles (its own sums of period), or returns early there (lastSuccessfulTime); it
    must be stepped to each exactly, else the event never fires, and on from there. t_event is
    the FMU's own time at its last event."""
    third = 1 / 3
    sc = write_scenario(tmp_path, {"ev": (c_fmus3["Thirds3"], {
        "period": third, "announce": announce, "tolerance": 0.0}, {"u": 0.0})}, stop=2.0)
    r = run_scenario(sc, build=False)
    events, t = [], 0.0
    for _ in range(6):
        t += third  # the FMU's own event times
        events.append(t)
    n, last = _last_tick(r.frame["time"].to_numpy(), np.array(events))
    np.testing.assert_array_equal(r.frame["ev.n"].to_numpy(), n)
    np.testing.assert_array_equal(r.frame["ev.t_event"].to_numpy(), last)


def _clock_run(c_fmus3, tmp_path, kind: str, parameters: dict) -> tuple:
    sc = write_scenario(tmp_path, {"c": (c_fmus3[f"Clocked{kind.title()}3"], parameters, {})},
                        stop=2.0)
    r = run_scenario(sc, build=False)
    return r.frame["time"].to_numpy(), r.frame["c.n"].to_numpy(), r.frame["c.q"].to_numpy()


# the FMU's parameters interval and shift are what it answers fmi3GetIntervalDecimal /
# fmi3GetShiftDecimal; a constant clock's come from its modelDescription (0.3 s, 0.1 s)
@pytest.mark.parametrize("kind, parameters", [
    ("constant", {"interval": 0.7, "shift": 0.5}),  # ignored: the modelDescription's hold
    ("fixed", {"interval": 0.3, "shift": 0.1}),
    ("typed", {"interval": 0.7, "shift": 0.5}),  # constant, interval from its ClockType
    ("declared", {"interval": 0.7, "shift": 0.5}),  # fixed, declaring 0.3 s and 0.1 s
    # tunable, declaring 0.3 s and 0.1 s: not asked, so growth does not retune it
    ("steady", {"interval": 0.7, "shift": 0.5, "growth": 2.0}),
])
def test_periodic_clocks_tick_at_shift_plus_multiples_of_the_interval(c_fmus3, tmp_path, kind,
                                                                      parameters):
    """Ticks at 0.1 + 0.3 k s (0.1, 0.4, 0.7, ...), each to the double of shift + k interval
    (exact rational, rounded once); q is the FMU's own time at its last tick."""
    times, n_ticks, q = _clock_run(c_fmus3, tmp_path, kind, parameters)
    ticks = np.array([float(Fraction(0.1) + k * Fraction(0.3)) for k in range(7)])
    assert ticks[:3].tolist() == pytest.approx([0.1, 0.4, 0.7], abs=1e-15)
    n, last = _last_tick(times, ticks)
    np.testing.assert_array_equal(n_ticks, n)
    np.testing.assert_array_equal(q, last)


def test_a_clock_that_supports_fraction_ticks_at_its_exact_fractions(c_fmus3, tmp_path):
    """A fixed clock with supportsFraction: interval 2/6 s and shift 1/6 s asked with
    fmi3GetIntervalFraction / fmi3GetShiftFraction (its decimal answers, 0.7 and 0.5 s, are
    not asked): ticks at 1/6 + k/3 s, each the double nearest the exact fraction."""
    times, n_ticks, q = _clock_run(c_fmus3, tmp_path, "fraction", {
        "interval": 0.7, "shift": 0.5, "interval_counter": 2, "shift_counter": 1,
        "resolution": 6})
    ticks = np.array([float(Fraction(1, 6) + Fraction(k, 3)) for k in range(6)])
    n, last = _last_tick(times, ticks)
    np.testing.assert_array_equal(n_ticks, n)
    np.testing.assert_array_equal(q, last)


def test_a_tunable_clock_ticks_at_the_intervals_the_fmu_retunes_to(c_fmus3, tmp_path):
    """interval 0.1 s, shift 0.1 s, doubled by the FMU at every tick (fmi3IntervalChanged in
    Event Mode): ticks at 0.1, 0.1 + 0.2, + 0.4, + 0.8 = 0.1, 0.3, 0.7, 1.5 s."""
    times, n_ticks, q = _clock_run(c_fmus3, tmp_path, "tunable",
                                   {"interval": 0.1, "shift": 0.1, "growth": 2.0})
    ticks, t = [0.1], Fraction(0.1)
    for k in range(1, 4):
        t += Fraction(0.1) * 2**k
        ticks.append(float(t))
    n, last = _last_tick(times, np.array(ticks))
    np.testing.assert_array_equal(n_ticks, n)
    np.testing.assert_array_equal(q, last)


def test_a_changing_clock_ticks_at_the_intervals_the_fmu_gives_where_it_ticked(c_fmus3,
                                                                               tmp_path):
    """A changing clock (FMI 3.0 sec. 2.2.8.2: t_0 = t_start + T_interval,0, asked in
    Initialization Mode; t_i = t_(i-1) + T_interval,i, asked in the Event Mode where it
    ticked): interval 0.1 s, multiplied by 2 at every tick: ticks at 0.1, 0.3, 0.7, 1.5 s."""
    times, n_ticks, q = _clock_run(c_fmus3, tmp_path, "changing",
                                   {"interval": 0.1, "growth": 2.0})
    ticks, t = [0.1], Fraction(0.1)
    for k in range(1, 4):
        t += Fraction(0.1) * 2**k
        ticks.append(float(t))
    n, last = _last_tick(times, np.array(ticks))
    np.testing.assert_array_equal(n_ticks, n)
    np.testing.assert_array_equal(q, last)


def test_a_clock_attribute_that_is_not_valid_names_the_variable(c_fmus3, tmp_path):
    from cosim.run.master.fmi3 import clock_attributes

    path = tmp_path / "bad.fmu"
    with zipfile.ZipFile(c_fmus3["ClockedConstant3"]) as src, zipfile.ZipFile(path, "w") as out:
        for item in src.namelist():
            data = src.read(item)
            if item == "modelDescription.xml":
                data = data.replace(b'intervalDecimal="0.3"', b'intervalDecimal="-0.3"')
            out.writestr(item, data)
    with pytest.raises(SimulationError, match=r"bad.fmu: modelDescription.xml: Clock 'tick' "
                                              r"intervalDecimal = '-0.3': must be > 0"):
        clock_attributes(path)
    assert clock_attributes(c_fmus3["ClockedConstant3"])[10].interval == Fraction(0.3)


def test_a_clock_takes_the_attributes_of_its_clock_type_it_does_not_declare(c_fmus3, tmp_path):
    """ClockedTyped3's clock: intervalDecimal from its ClockType, its own shiftDecimal over the
    type's (FMI 3.0 sec. 2.4.4); a declaredType with no ClockType names the type."""
    from cosim.run.master.fmi3 import clock_attributes

    tick = clock_attributes(c_fmus3["ClockedTyped3"])[10]
    assert (tick.interval_variability, tick.interval, tick.shift) == (
        "constant", Fraction(0.3), Fraction(0.1))
    path = tmp_path / "untyped.fmu"
    with zipfile.ZipFile(c_fmus3["ClockedTyped3"]) as src, zipfile.ZipFile(path, "w") as out:
        for item in src.namelist():
            data = src.read(item)
            if item == "modelDescription.xml":
                data = data.replace(b'declaredType="Tick"', b'declaredType="Tock"')
            out.writestr(item, data)
    with pytest.raises(SimulationError, match=r"untyped.fmu: modelDescription.xml: Clock 'tick' "
                                              r"declaredType = 'Tock': no ClockType"):
        clock_attributes(path)


def test_unset_inputs_keep_their_start_values(c_fmus3, tmp_path, caplog):
    """Only u_Float64 given: every other input of the Feedthrough keeps its declared start
    value (y_T = u_T), and one log line lists them."""
    sc = write_scenario(tmp_path, {"ft": (c_fmus3["Feedthrough3"], {}, {"u_Float64": 0.25})},
                        record=["ft.y_Float64", "ft.y_Float32", "ft.y_Int64", "ft.y_Boolean",
                                "ft.ya[*]"], stop=0.5)
    with caplog.at_level("WARNING", logger="cosim.run.master.core"):
        r = run_scenario(sc, build=False)
    last = r.frame.iloc[-1]
    assert (last["ft.y_Float64"], last["ft.y_Float32"], last["ft.y_Int64"],
            last["ft.y_Boolean"]) == (0.25, 1.5, 1.0, 0.0)
    assert list(last[["ft.ya[1]", "ft.ya[2]", "ft.ya[3]"]]) == [0.0, 0.0, 0.0]
    lines = [rec.getMessage() for rec in caplog.records if "keep their start" in rec.getMessage()]
    assert len(lines) == 1
    assert "ft.u_Float32 = 1.5, ft.u_Int8 = 1" in lines[0] and "ft.ua[3] = 0" in lines[0]
    assert "u_Float64" not in lines[0]


def _triggered_run(c_fmus3, tmp_path, period: float) -> tuple:
    """Pulses3 (events at k period for k = 0, 1, 8, 9, its output clock "ticked" active at
    each) driving Triggered3's triggered input clock "tick", Triggered3's clocked input u its
    count n: (master, frame, Pulses3's tick times, Triggered3's tick times as it logged them)."""
    from cosim.run.master.core import Master
    from cosim.run.scenario import load_scenario

    sc = write_scenario(tmp_path, {"p": (c_fmus3["Pulses3"], {"period": period}, {}),
                                   "y": (c_fmus3["Triggered3"], {}, {})},
                        connections={"y.tick": "p.ticked", "y.u": "p.n"}, stop=10 * period,
                        output=period)
    master = Master(load_scenario(sc))
    frame = master.run().frame
    ticks = [k * period for k in (0, 1, 8, 9)]  # Pulses3's own doubles: j period in C
    logged = [float(m.removeprefix("tick at t = ")) for m in master.by_name["y"].messages
              if m.startswith("tick at t = ")]
    return master, frame, ticks, logged


@pytest.mark.parametrize("period", [1.0, 1 / 3])
def test_an_output_clock_triggers_a_co_simulation_fmus_triggered_clock(c_fmus3, tmp_path,
                                                                       period):
    """FMI 3.0 sec. 2.2.8.2 (triggered Clock: it ticks when the importer says, here when
    Pulses3's output clock does): Triggered3's clock ticks at Pulses3's event times exactly
    (the FMU's own time, also at 1/3 s multiples that are not whole nanoseconds), once each,
    in Event Mode (it refuses fmi3SetClock elsewhere, sec. 2.2.8.4), with its clocked input u
    set from Pulses3's count after Pulses3's event: y = 1, 2, 3, 4 at the ticks."""
    master, frame, ticks, logged = _triggered_run(c_fmus3, tmp_path, period)
    assert logged == ticks
    last = frame.iloc[-1]
    assert (last["y.n"], last["p.n"]) == (4, 4)
    assert last["y.q"] == ticks[-1]
    assert last["y.y"] == 4
    t = frame["time"].to_numpy()
    # a recorded time is the tick rounded to whole nanoseconds: within 0.5 ns of it
    expected_y = np.array([sum(s <= x + 0.5e-9 for s in ticks) for x in t])
    np.testing.assert_array_equal(frame["y.y"].to_numpy(), expected_y)
    np.testing.assert_array_equal(frame["y.n"].to_numpy(), expected_y)


def test_a_triggered_clock_must_be_connected_to_an_output_clock(c_fmus3, tmp_path):
    """A co-simulation FMU's triggered input clock wired to nothing would never tick (FMI 3.0
    sec. 2.2.8.2), one wired to a variable that is not a Clock cannot: both refused, naming
    the scenario file, the key and its value."""
    from cosim.run.master.core import Master
    from cosim.run.scenario import ScenarioError, load_scenario

    fmu = c_fmus3["Triggered3"]
    sc = write_scenario(tmp_path, {"y": (fmu, {}, {})})
    with pytest.raises(ScenarioError, match=(
            rf"{sc}: \[fmus.y\] fmu = '{fmu}': input Clock 'tick' is triggered "
            r".*no output Clock is connected to it")):
        Master(load_scenario(sc)).run()
    sc = write_scenario(tmp_path, {"p": (c_fmus3["Pulses3"], {}, {}), "y": (fmu, {}, {})},
                        connections={"y.tick": "p.n"})
    with pytest.raises(ScenarioError, match=(
            rf"{sc}: \[connections\] \"y.tick\" = \"p.n\": p.n is not an output Clock")):
        Master(load_scenario(sc)).run()


def test_a_source_returning_early_triggers_at_its_own_event_time(c_fmus3, tmp_path):
    """Ticker3 (events every 0.1 s, its own sums of 0.1, not announced: it returns early at
    each, FMI 3.0 sec. 4.1.3; its output clock "ticked" active there) driving Triggered3: the
    triggered FMU steps after the source, so it is at the source's early-return time and its
    clock ticks there exactly (0.30000000000000004 s and the like are not whole nanoseconds:
    the source's double), with u = the source's count after its event; stop 0.95 s, before
    the tenth event (within Ticker3's tolerance of 1.0 s, where it would not return early)."""
    from cosim.run.master.core import Master
    from cosim.run.scenario import load_scenario

    sc = write_scenario(tmp_path, {"y": (c_fmus3["Triggered3"], {}, {}),
                                   "p": (c_fmus3["Ticker3"], {"announce": False}, {})},
                        connections={"y.tick": "p.ticked", "y.u": "p.n"}, stop=0.95)
    master = Master(load_scenario(sc))
    frame = master.run().frame
    ticks, t = [], 0.0
    for _ in range(9):  # up to 0.8999999999999999 s (the next, 0.9999999999999999, after 0.95)
        t += 0.1  # the FMU's own event times (m->next += period in C)
        ticks.append(t)
    logged = [float(m.removeprefix("tick at t = ")) for m in master.by_name["y"].messages
              if m.startswith("tick at t = ")]
    assert logged == ticks
    last = frame.iloc[-1]
    assert (last["y.n"], last["y.y"], last["p.n"]) == (9, 9, 9)
