"""The event-driven algorithm's C loop (:mod:`cosim.run.master.native_loop`) against its Python
loop: the same run bit for bit (every recorded value, doStep count, connection change count and
passed-on value, final output, end time and who ended the run) on third-party C FMUs that
refuse steps and retry them, end the run, cannot vary their step, pass every numeric type, and
on the package's own Python and native builds (sampled and self-triggered controllers); also
when the C loop hands back to Python after every point, drains its connection histories every
value and outgrows its recording; an FMU failing inside it fails the run as in Python."""

from __future__ import annotations

import ctypes
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from test_master_third_party import write_scenario

from cosim.run.master import SimulationError, core, native_loop
from cosim.run.master.observers import Recorder
from cosim.run.scenario import load_scenario
from cosim.run.simulate import ensure_built, run_scenario


@pytest.fixture(autouse=True)
def compiled_loop() -> None:
    """The C loop is built here (it needs gcc, as the C test FMUs do)."""
    if native_loop.library() is None:
        pytest.skip("no C compiler: the event master's C loop cannot be built")


def _outcome(result: Any) -> dict[str, Any]:
    """Everything a run produces but its wall times; floats compared by their bits."""
    frame = result.frame
    return {"columns": list(frame.columns),
            "values": [frame[c].to_numpy().tobytes() for c in frame.columns],
            "do_steps": result.do_steps, "executions": result.executions,
            "changes": result.connection_changes, "passed": repr(result.connection_values),
            "final": repr(result.final_outputs), "sim_time_s": result.sim_time_s,
            "terminated_by": result.terminated_by, "completed": result.completed}


def _run(monkeypatch, scenario: Any, loop: str, **kwargs: Any) -> tuple[Any, int]:
    """Run ``scenario`` on the ``loop`` ("python" or "c"): (result, C loops run)."""
    runs = []
    real = native_loop.NativeLoop.run

    def counted(self: Any) -> None:
        runs.append(self)
        real(self)

    with monkeypatch.context() as m:
        m.setattr(native_loop.NativeLoop, "run", counted)
        m.setenv(native_loop.ENV, "off" if loop == "python" else "on")
        result = run_scenario(scenario, build=False, plot=False, **kwargs)
    return result, len(runs)


def assert_loops_agree(monkeypatch, scenario: Any, **kwargs: Any) -> Any:
    """The C loop ran and its run equals the Python loop's; the result."""
    python, c_runs = _run(monkeypatch, scenario, "python", **kwargs)
    assert c_runs == 0
    c, c_runs = _run(monkeypatch, scenario, "c", **kwargs)
    assert c_runs == 1, "the C loop did not run"
    assert _outcome(c) == _outcome(python)
    return c


def _third_party(c_fmus: dict[str, Path], tmp_path: Path, case: str) -> Path:
    f = c_fmus
    if case == "refused steps retried":  # Discarder: 0.5 s steps refused down to 0.125 s
        return write_scenario(tmp_path, {"d": (f["Discarder"], {}, {"u": 1.0})},
                              base_step=0.5, output=0.5, stop=2.0)
    if case == "an FMU ends the run":
        return write_scenario(tmp_path, {"term": (f["Terminator"], {"stop_at": 0.5}, {}),
                                         "ev": (f["Events"], {}, {})}, {"ev.u": "term.x"})
    if case == "fixed-step FMU among max_step points":
        return write_scenario(tmp_path, {"fixed": (f["DiscarderFixed"], {}, {"u": 1.0}),
                                         "other": (f["Feedthrough"], {"k": 1.0}, {"u": 1.0})},
                              extra={"other": {"max_step": 0.05}})
    if case == "default experiment step":
        return write_scenario(tmp_path, {"fixed": (f["DiscarderFixedStep"],
                                                   {"max_step": 0.05}, {"u": 1.0})})
    if case == "feedthrough chain":
        return write_scenario(tmp_path, {"a": (f["Feedthrough"], {"k": 2.0}, {"u": 0.5}),
                                         "b": (f["Feedthrough"], {"k": -1.0}, {})},
                              {"b.u": "a.y"}, stop=2.0, output=0.25)
    if case == "every numeric type":  # Real, Integer, Enumeration (an Integer), Boolean
        names = ("y", "yi", "next_mode", "yb")
        path = write_scenario(
            tmp_path, {"A": (f["AllTypes"], {}, {"mode": "fast", "u": 1.0, "ui": 2,
                                                 "ub": True}),
                       "B": (f["AllTypes"], {}, {})},
            {f"B.{i}": f"A.{o}" for i, o in zip(("u", "ui", "mode", "ub"), names)},
            record=[f"{c}.{n}" for c in "AB" for n in names], stop=3.0)
        # the summary's command connection keeps every new value it passes on
        path.write_text(path.read_text() + '[summary]\ncommand = "A.yi"\n')
        return path
    raise KeyError(case)


CASES = ("refused steps retried", "an FMU ends the run", "fixed-step FMU among max_step points",
         "default experiment step", "feedthrough chain", "every numeric type")


@pytest.mark.parametrize("case", CASES)
def test_c_loop_equals_python_loop_on_third_party_fmus(c_fmus, tmp_path, monkeypatch, case):
    result = assert_loops_agree(monkeypatch, _third_party(c_fmus, tmp_path, case))
    assert result.completed


@pytest.mark.parametrize("case", ["every numeric type", "fixed-step FMU among max_step points",
                                  "refused steps retried"])
def test_c_loop_handing_back_at_every_point_equals_python_loop(c_fmus, tmp_path, monkeypatch,
                                                               case):
    """No time budget (back to Python, progress reported, after every point), a history
    buffer of one value (drained at every return) and a recording of one row (grown from
    Python): the same run, and progress reported at the same points as the Python loop."""
    monkeypatch.setattr(native_loop, "BUDGET", 0.0)
    monkeypatch.setattr(native_loop, "HISTORY", 1)
    monkeypatch.setattr(core, "Recorder", lambda refs, n_points: Recorder(refs, 1))
    scenario = _third_party(c_fmus, tmp_path, case)
    seen: dict[str, list[float]] = {"python": [], "c": []}
    results = {loop: _run(monkeypatch, scenario, loop,
                          progress=lambda t, total, loop=loop: seen[loop].append(t))
               for loop in seen}
    assert results["python"][1] == 0 and results["c"][1] == 1
    assert _outcome(results["c"][0]) == _outcome(results["python"][0])
    assert seen["c"] == seen["python"]
    sc = load_scenario(scenario)
    assert seen["c"][-1] == sc.simulation.stop_time
    assert len(seen["c"]) >= round(sc.simulation.stop_time / sc.simulation.output_interval)


def test_a_step_error_inside_the_c_loop_fails_the_run_as_in_python(c_fmus, tmp_path,
                                                                   monkeypatch):
    """A fixed-step FMU refusing its step (fmi2Discard, it cannot take a smaller one): the same
    error and the same partial result from either loop."""
    path = write_scenario(tmp_path, {"d": (c_fmus["DiscarderFixedStep"], {"max_step": 0.05},
                                           {"u": 1.0}),
                                     "a": (c_fmus["Feedthrough"], {"k": 1.0}, {"u": 1.0})},
                          stop=2.0, extra={"d": {"max_step": 0.1}})
    errors, partial = [], []
    for loop in ("python", "c"):
        out = tmp_path / loop
        with monkeypatch.context() as m:
            m.setenv(native_loop.ENV, "off" if loop == "python" else "on")
            with pytest.raises(SimulationError) as err:
                run_scenario(path, build=False, plot=False, out_dir=out)
        errors.append(str(err.value).replace(str(out), "OUT"))
        partial.append((out / "results.csv").read_bytes())
    assert "fmi2Discard" in errors[0] and errors[0] == errors[1]
    assert partial[0] == partial[1]


@pytest.mark.parametrize("recorded", [True, False], ids=["read in the row", "read alone"])
def test_an_announced_event_not_in_the_future_fails_the_run_as_in_python(c_fmus, tmp_path,
                                                                         monkeypatch, recorded):
    """An FMU announcing its next event at 0.5 s, and again at 0.5 s when it is there: the same
    error naming both times, and the same partial result, from either loop; its announcement
    read with the output row (recorded) or by a get of its own (not recorded)."""
    record = ["a.z", "a.next_event_time"] if recorded else ["a.z"]
    path = write_scenario(tmp_path, {"a": (c_fmus["Announcer"], {"k": 1.0}, {"u": 0.5})}, stop=2.0,
                          output=0.75, record=record)
    errors, partial = [], []
    for loop in ("python", "c"):
        out = tmp_path / loop
        with monkeypatch.context() as m:
            m.setenv(native_loop.ENV, "off" if loop == "python" else "on")
            with pytest.raises(SimulationError) as err:
                run_scenario(path, build=False, plot=False, out_dir=out)
        errors.append(str(err.value).replace(str(out), "OUT"))
        partial.append((out / "results.csv").read_bytes())
    assert errors[0].startswith("a: next_event_time = 0.5 s is not after the current time 0.5 s")
    assert errors[0] == errors[1] and partial[0] == partial[1]


def test_a_failed_get_inside_the_c_loop_fails_the_run_as_in_python(c_fmus, tmp_path,
                                                                   monkeypatch):
    """An output whose value reference the FMU's binary lacks: its first read (the recording
    at t = 0) fails with the same error, naming the FMU, the call and what the FMU logged."""
    path = write_scenario(tmp_path, {"a": (c_fmus["Feedthrough"], {}, {"u": 1.0}),
                                     "b": (c_fmus["BadReference"], {}, {})}, {"b.u": "a.y"})
    errors = []
    for loop in ("python", "c"):
        with monkeypatch.context() as m:
            m.setenv(native_loop.ENV, "off" if loop == "python" else "on")
            with pytest.raises(SimulationError) as err:
                run_scenario(path, build=False, plot=False)
        errors.append(str(err.value))
    assert errors[0].startswith("b: getReal at t = 0 s failed") and "reference 9" in errors[0]
    assert errors[0] == errors[1]


@pytest.mark.parametrize("scenario, build", [
    ("seed000_stop_pid", "python"),  # a sampled controller, the summary's command history
    ("seed000_stop_rsmpc", "python"),  # a self-triggered controller (next_event_time)
    ("seed000_stop_rsmpc", "native"),
    ("seed001_emu_pid", "native"),  # sub-stepped couplers, force shared over three units
])
def test_c_loop_equals_python_loop_on_our_fmus(built_fmus, monkeypatch, scenario, build):
    sc = load_scenario(scenario)
    overrides = {f"{name}.build": build for name in sc.components} if build != "python" else {}
    ensure_built(load_scenario(scenario, overrides))
    quick = {"simulation.stop_time": 60.0} if scenario == "seed001_emu_pid" else {}
    assert_loops_agree(monkeypatch, scenario, overrides={**overrides, **quick})


def test_what_the_c_loop_cannot_run_stays_in_python(c_fmus, tmp_path, monkeypatch):
    """A String connection: the Python loop runs it (and says why in the debug log)."""
    f = c_fmus["AllTypes"]
    path = write_scenario(tmp_path, {"A": (f, {}, {}), "B": (f, {}, {})}, {"B.us": "A.ys"})
    result, c_runs = _run(monkeypatch, path, "c")
    assert result.completed and c_runs == 0


def test_the_c_loop_structures_match_their_c_declarations() -> None:
    """The ctypes mirrors of the C structs have the C sizes (compiled here: a probe of
    sizeof in the same translation unit)."""
    lib = native_loop.library()
    sizes = {name: getattr(native_loop, name) for name in ("COp", "CPlan", "CUnit", "CLink",
                                                           "CLoop")}
    for name, cls in sizes.items():
        fn = getattr(lib, f"native_loop_sizeof_{name[1:].lower()}")
        fn.restype = ctypes.c_size_t
        assert fn() == ctypes.sizeof(cls), name
    assert np.dtype(np.float64).itemsize == ctypes.sizeof(ctypes.c_double)
