"""Our master with third-party FMI 2.0 co-simulation FMUs (plain C, tests/third_party): every
variable type incl. Enumeration, an FMU that ends the run (fmi2Discard + fmi2Terminated), one
that refuses long steps, direct feedthrough with and without a ``dependencies`` attribute,
events inside a step. Alone, each run equals ``fmpy.simulate_fmu`` on the same FMU exactly (both
make the same FMI calls with the same arguments on binary-exact step sizes)."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
from fmpy import simulate_fmu
from third_party_fmus import MODE_ITEMS

from cosim.run.master import SimulationError, native_loop
from cosim.run.scenario import ScenarioError, load_scenario
from cosim.run.simulate import run_scenario

ALGORITHMS = ("event", "fixed", "jacobi")
H = 0.125  # binary-exact step: the same times in both masters


def toml_value(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return json.dumps(value)
    return repr(value)


def write_scenario(tmp_path: Path, fmus: dict[str, tuple[Path, dict, dict]],
                   connections: dict[str, str] | None = None, stop: float = 1.0,
                   algorithm: str = "event", base_step: float = H, output: float = H,
                   record: list[str] | None = None, extra: dict | None = None) -> Path:
    """A scenario file: ``fmus`` name -> (path, parameters, inputs)."""
    lines = ["[simulation]", f"stop_time = {stop!r}", f"output_interval = {output!r}",
             f'algorithm = "{algorithm}"', f"base_step = {base_step!r}"]
    for name, (path, params, inputs) in fmus.items():
        lines += [f"[fmus.{name}]", f'fmu = "{path}"']
        for key, value in (extra or {}).get(name, {}).items():
            lines.append(f"{key} = {toml_value(value)}")
        lines.append(f"[fmus.{name}.parameters]")
        lines += [f"{k} = {toml_value(v)}" for k, v in params.items()]
        lines.append(f"[fmus.{name}.inputs]")
        lines += [f"{k} = {toml_value(v)}" for k, v in inputs.items()]
    lines.append("[connections]")
    lines += [f'"{dst}" = "{src}"' for dst, src in (connections or {}).items()]
    if record is not None:
        lines += ["[record]", f"variables = {json.dumps(record)}"]
    path = tmp_path / "scenario.toml"
    path.write_text("\n".join(lines) + "\n")
    return path


def assert_same_as_fmpy(result, fmu: Path, name: str, start_values: dict, stop: float,
                        outputs: list[str]) -> None:
    ref = simulate_fmu(str(fmu), stop_time=stop, output_interval=H, start_values=start_values,
                       output=outputs)
    # fmpy samples the end point again when an FMU terminates (force=True): one row per time
    _, first = np.unique(ref["time"], return_index=True)
    ref = ref[first]
    frame = result.frame
    np.testing.assert_array_equal(frame["time"].to_numpy(), ref["time"])
    for out in outputs:
        np.testing.assert_array_equal(frame[f"{name}.{out}"].to_numpy(dtype=float),
                                      ref[out].astype(float), err_msg=out)


CASES = {
    # name: (parameters, inputs, outputs compared, stop time)
    "AllTypes": ({"gain": 1.5, "offset": -3, "invert": True, "label": "x", "level": "normal"},
                 {"u": 0.25, "ui": 7, "ub": False, "mode": 2, "us": "s"},
                 ["y", "yi", "next_mode", "yb"], 1.0),
    "Terminator": ({"stop_at": 0.625}, {}, ["x", "steps"], 1.0),
    "Discarder": ({}, {"u": 0.75}, ["x"], 1.0),
    "Feedthrough": ({"k": 2.0}, {"u": 0.5}, ["y", "z"], 1.0),
    "Events": ({"period": 0.1}, {"u": 0.5}, ["q", "n"], 1.0),
}


@pytest.mark.parametrize("algorithm", ALGORITHMS)
@pytest.mark.parametrize("name", sorted(CASES))
def test_alone_equals_fmpy(c_fmus, tmp_path, name, algorithm):
    params, inputs, outputs, stop = CASES[name]
    path = write_scenario(tmp_path, {"m": (c_fmus[name], params, inputs)}, stop=stop,
                          algorithm=algorithm)
    result = run_scenario(path, build=False, plot=False)
    assert result.completed
    # fmpy takes an Enumeration by value only
    values = {k: MODE_ITEMS.index(v) + 1 if k == "level" else v
              for k, v in {**params, **inputs}.items()}
    assert_same_as_fmpy(result, c_fmus[name], "m", values, stop, outputs)


def test_enumeration_by_item_name_and_every_type_through_connections(c_fmus, tmp_path):
    """A -> B with every type (Real, Integer, Enumeration, Boolean, String); A's Enumeration
    input given by item name. No feedthrough: B at t + h computes from A's outputs at t."""
    f = c_fmus["AllTypes"]
    names = ("y", "yi", "next_mode", "yb", "ys")
    conn = {f"B.{i}": f"A.{o}" for i, o in zip(("u", "ui", "mode", "ub", "us"), names)}
    for algorithm in ALGORITHMS:
        path = write_scenario(tmp_path, {"A": (f, {"label": "a"}, {"mode": "fast", "u": 1.0,
                                                                   "ui": 2, "ub": True,
                                                                   "us": "z"}),
                                         "B": (f, {}, {})}, conn, algorithm=algorithm,
                              record=[f"{c}.{n}" for c in "AB" for n in names])
        fr = run_scenario(path, build=False, plot=False).frame
        t = fr["time"].to_numpy()
        assert (fr["A.next_mode"].to_numpy()[1:] == 1).all()  # fast (3) -> slow (1)
        np.testing.assert_array_equal(fr["B.y"].to_numpy()[1:],
                                      2.0 * fr["A.y"].to_numpy()[:-1] + t[1:])
        np.testing.assert_array_equal(fr["B.yi"].to_numpy()[1:],
                                      10 + fr["A.yi"].to_numpy()[:-1] + np.floor(4 * t[1:]))
        np.testing.assert_array_equal(fr["B.next_mode"].to_numpy()[1:],
                                      fr["A.next_mode"].to_numpy()[:-1] % 3 + 1)
        np.testing.assert_array_equal(fr["B.yb"].to_numpy()[1:], fr["A.yb"].to_numpy()[:-1])
        assert list(fr["A.ys"])[1:] == ["a:z"] * (len(t) - 1)
        assert list(fr["B.ys"])[2:] == ["tag:a:z"] * (len(t) - 2)


@pytest.mark.parametrize("value, message", [
    ("faster", "'faster' is not one of its items: slow (1), normal (2), fast (3)"),
    (4, "4 is not an item value"),
    (1.5, "got 1.5"),
])
def test_bad_enumeration_value_is_a_clear_error(c_fmus, tmp_path, value, message):
    path = write_scenario(tmp_path, {"A": (c_fmus["AllTypes"], {}, {"mode": value})})
    with pytest.raises(ScenarioError, match=re.escape(f"[fmus.A.inputs] mode: A.mode is an "
                                                      f"Enumeration, {message}")):
        run_scenario(path, build=False, plot=False)


def test_connection_type_mismatch_is_rejected(c_fmus, tmp_path):
    f = c_fmus["AllTypes"]
    path = write_scenario(tmp_path, {"A": (f, {}, {}), "B": (f, {}, {"ui": 1})},
                          {"B.mode": "A.yi"})
    with pytest.raises(ScenarioError, match="type mismatch: A.yi is Integer, B.mode is "
                                            "Enumeration"):
        run_scenario(path, build=False, plot=False)


@pytest.mark.parametrize("algorithm", ALGORITHMS)
def test_fmu_ending_the_run_completes_it(c_fmus, tmp_path, algorithm):
    out = tmp_path / "out"
    path = write_scenario(tmp_path, {"term": (c_fmus["Terminator"], {"stop_at": 0.5}, {}),
                                     "ev": (c_fmus["Events"], {}, {})},
                          {"ev.u": "term.x"}, algorithm=algorithm)
    result = run_scenario(path, build=False, plot=False, out_dir=out)
    assert result.completed and result.terminated_by == {"instance": "term", "time": 0.5}
    assert result.frame["time"].iloc[-1] == 0.5
    summary = json.loads((out / "summary.json").read_text())
    assert summary["completed"] is True
    assert summary["terminated_by"] == {"instance": "term", "time": 0.5}


@pytest.mark.parametrize("algorithm", ALGORITHMS)
def test_discarded_step_is_retried_in_pieces(c_fmus, tmp_path, algorithm):
    """max_step 0.125, communication steps of 0.5: each is refused once per halving
    (0.5, 0.25) and then done in pieces of 0.125; x' = u exactly."""
    path = write_scenario(tmp_path, {"d": (c_fmus["Discarder"], {}, {"u": 1.0})},
                          algorithm=algorithm, base_step=0.5, output=0.5, stop=2.0)
    result = run_scenario(path, build=False, plot=False)
    np.testing.assert_array_equal(result.frame["d.x"].to_numpy(), [0.0, 0.5, 1.0, 1.5, 2.0])
    assert result.do_steps["d"] == 4 * (4 + 2)  # 4 steps: 4 pieces + 2 refusals each


def test_discard_without_variable_steps_is_a_clear_error(c_fmus, tmp_path):
    path = write_scenario(tmp_path, {"d": (c_fmus["DiscarderFixed"], {}, {"u": 1.0})},
                          algorithm="fixed", base_step=0.25, output=0.25)
    with pytest.raises(SimulationError, match=r"d: doStep at t=0.0 s, h=0.25 s returned "
                       r"fmi2Discard .* cannot handle variable communication step sizes.*"
                       r"max_step = 0.125"):
        run_scenario(path, build=False, plot=False)


@pytest.mark.parametrize("feed", ["Feedthrough", "FeedthroughUndeclared"])
@pytest.mark.parametrize("algorithm", ["event", "fixed"])
def test_feedthrough_values_flow_in_order(c_fmus, tmp_path, feed, algorithm):
    """source.x -> f.u, f.y = 3 u -> sink.u, the sink's connection listed first: with the
    dependency (declared, or implied by an absent attribute) the sink gets 3 x of the same
    instant."""
    path = write_scenario(tmp_path, {"sink": (c_fmus["Events"], {}, {}),
                                     "f": (c_fmus[feed], {}, {}),
                                     "src": (c_fmus["Discarder"], {}, {"u": 1.0})},
                          {"sink.u": "f.y", "f.u": "src.x"}, algorithm=algorithm,
                          record=["src.x", "f.y", "sink.u"])
    fr = run_scenario(path, build=False, plot=False).frame
    np.testing.assert_array_equal(fr["sink.u"].to_numpy(), 3.0 * fr["src.x"].to_numpy())
    assert fr["src.x"].iloc[-1] == 1.0


@pytest.mark.parametrize("feed", ["Feedthrough", "FeedthroughUndeclared"])
def test_self_loop_is_rejected_like_a_two_fmu_loop(c_fmus, tmp_path, feed):
    path = write_scenario(tmp_path, {"f": (c_fmus[feed], {}, {})}, {"f.u": "f.y"})
    with pytest.raises(ScenarioError, match=r"algebraic loop .*: f.y -> f.y"):
        run_scenario(path, build=False, plot=False)
    path = write_scenario(tmp_path, {"f": (c_fmus[feed], {}, {}), "g": (c_fmus[feed], {}, {})},
                          {"f.u": "g.y", "g.u": "f.y"})
    with pytest.raises(ScenarioError, match=r"algebraic loop .*: (f.y -> g.y -> f.y|"
                                            r"g.y -> f.y -> g.y)"):
        run_scenario(path, build=False, plot=False)


def test_self_connection_through_a_state_output_runs(c_fmus, tmp_path):
    """z = integral of u does not depend on u (declared): f.z -> f.u is no algebraic loop;
    without the declaration it would be one."""
    path = write_scenario(tmp_path, {"f": (c_fmus["Feedthrough"], {}, {})}, {"f.u": "f.z"},
                          record=["f.z"])
    assert run_scenario(path, build=False, plot=False).completed
    path = write_scenario(tmp_path, {"f": (c_fmus["FeedthroughUndeclared"], {}, {})},
                          {"f.u": "f.z"})
    with pytest.raises(ScenarioError, match="algebraic loop"):
        load_scenario(path) and run_scenario(path, build=False, plot=False)


def test_event_master_steps_a_fixed_step_fmu_on_its_own_grid(c_fmus, tmp_path, monkeypatch):
    """canHandleVariableCommunicationStepSize = false (issue 24): among the points another
    FMU's max_step = 0.05 s and the 0.125 s output grid make, the event algorithm steps it by
    0.125 s (base_step) only, every step the same size."""
    from cosim.run import master as master_mod

    sizes: dict[str, set[int]] = {}
    real = master_mod.Fmi2Unit._do_step

    def do_step(self, t, h):
        sizes.setdefault(self.name, set()).add(h)
        return real(self, t, h)

    monkeypatch.setattr(master_mod.Fmi2Unit, "_do_step", do_step)
    monkeypatch.setenv(native_loop.ENV, "off")  # the Python loop's calls (the C loop's: equal)
    sc = write_scenario(tmp_path, {"fixed": (c_fmus["DiscarderFixed"], {}, {"u": 1.0}),
                                   "other": (c_fmus["Feedthrough"], {"k": 1.0}, {"u": 1.0})},
                        extra={"other": {"max_step": 0.05}})
    r = run_scenario(sc, build=False)
    assert sizes["fixed"] == {125_000_000}
    assert len(sizes["other"]) > 1  # the points between are there
    np.testing.assert_allclose(r.frame["fixed.x"], r.frame["time"], rtol=0, atol=1e-12)


def test_event_master_steps_a_fixed_step_fmu_at_its_default_experiment_step(c_fmus, tmp_path,
                                                                           monkeypatch):
    """canHandleVariableCommunicationStepSize = false and DefaultExperiment stepSize = 0.05 s:
    the event algorithm steps it by 0.05 s (not the 0.125 s base step and output interval),
    20 steps over 1 s; x = integral of u = 1 is the FMU's own time (its last step's end) at
    every output point."""
    from cosim.run import master as master_mod

    steps: list[tuple[int, int]] = []
    real = master_mod.Fmi2Unit._do_step

    def do_step(self, t, h):
        steps.append((t, h))
        return real(self, t, h)

    monkeypatch.setattr(master_mod.Fmi2Unit, "_do_step", do_step)
    monkeypatch.setenv(native_loop.ENV, "off")  # the Python loop's calls (the C loop's: equal)
    sc = write_scenario(tmp_path, {"fixed": (c_fmus["DiscarderFixedStep"], {"max_step": 0.05},
                                             {"u": 1.0})})
    r = run_scenario(sc, build=False)
    assert steps == [(k * 50_000_000, 50_000_000) for k in range(20)]
    own_time = np.floor(r.frame["time"].to_numpy() / 0.05 + 1e-9) * 0.05
    np.testing.assert_allclose(r.frame["fixed.x"], own_time, rtol=0, atol=1e-12)


def test_unset_input_of_a_third_party_fmu_keeps_its_start_value(c_fmus, tmp_path, caplog):
    """The Feedthrough's u (start 0.0) neither connected nor set: y = k u and z = integral of
    u stay 0, and the log says once that u keeps its start value."""
    sc = write_scenario(tmp_path, {"f": (c_fmus["Feedthrough"], {"k": 2.0}, {})},
                        record=["f.y", "f.z"])
    with caplog.at_level("WARNING", logger="cosim.run.master.core"):
        r = run_scenario(sc, build=False)
    assert (r.frame["f.y"] == 0.0).all() and (r.frame["f.z"] == 0.0).all()
    assert [rec.getMessage() for rec in caplog.records] == [
        f"{sc}: inputs neither connected nor set keep their start values: f.u = 0.0"]


def test_fixed_step_fmu_on_a_grid_that_misses_the_stop_time_asks_for_a_max_step(c_fmus,
                                                                               tmp_path):
    sc = write_scenario(tmp_path, {"fixed": (c_fmus["DiscarderFixed"], {}, {"u": 1.0})},
                        stop=1.1, base_step=0.125)
    with pytest.raises(SimulationError, match=r"\[fmus.fixed\].*cannot handle variable.*"
                                              r"algorithm = \"fixed\""):
        run_scenario(sc, build=False)
