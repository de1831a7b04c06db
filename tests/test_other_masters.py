"""Our FMUs under other masters: libcosim (fixed step) must match our master's Jacobi mode
to 1e-9 on every shipped scenario (whole runs: one per pair of FMUs); fmpy's simulate_fmu
replays a plant from recorded inputs."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from matrix import by_scenario
from scenario_groups import one_per_fmu_pair

from cosim.interop.libcosim import compare_frames, run_libcosim, simulate_single
from cosim.run.scenario import find_scenario, load_scenario, scenario_files
from cosim.run.simulate import run_scenario

SCENARIOS = list(scenario_files().values())
SHORT = 40.0  # s of each scenario in the quick test; the full runs are marked slow


def _ours_and_libcosim(path: Path, stop_time: float | None, isolated: bool = True):
    """The scenario, our Jacobi run's frame and libcosim's (in a child process unless
    ``isolated`` is false: the frames equal either way, and the child path is tested on
    its own below)."""
    overrides = {"simulation.stop_time": stop_time} if stop_time else None
    sc = load_scenario(path, overrides)
    ours = run_scenario(sc, algorithm="jacobi", plot=False).frame
    theirs = run_libcosim(sc, isolated=isolated)
    return sc, ours, theirs


def _assert_match(sc, ours, theirs) -> None:
    diffs = compare_frames(ours, theirs)
    assert diffs and len(diffs) == len(theirs.columns) - 1
    assert not theirs.drop(columns="time").isna().to_numpy().any()
    h = sc.simulation.base_step or sc.simulation.output_interval
    assert len(theirs) == round(sc.simulation.stop_time / h)
    worst = max(diffs, key=diffs.get)
    assert diffs[worst] <= 1e-9, f"{sc.name}: {worst} differs by {diffs[worst]:.3e}"


@pytest.mark.parametrize("path", by_scenario(SCENARIOS))
def test_libcosim_matches_jacobi(path, built_fmus):
    """libcosim in this process (``isolated=False``): the equality does not depend on the
    process libcosim runs in; the isolated path is
    test_libcosim_delivers_the_command_one_step_later's and
    test_libcosim_aborting_its_process_is_an_error_here_not_an_exit's."""
    sc, ours, theirs = _ours_and_libcosim(path, SHORT, isolated=False)
    _assert_match(sc, ours, theirs)


@pytest.mark.slow
@pytest.mark.parametrize("name", one_per_fmu_pair())
def test_libcosim_matches_jacobi_full_run(name, built_fmus):
    """Whole runs, one scenario per pair of FMUs (:mod:`scenario_groups`)."""
    sc, ours, theirs = _ours_and_libcosim(find_scenario(name), None)
    _assert_match(sc, ours, theirs)


def _one_step_late(frame) -> bool:
    """Whether, on every sample after the first, the controller computed from the plant
    outputs of the previous sample (its v_ref is the stopping curve at the previous position)
    and the plant holds the previous sample's command: the Jacobi exchange."""
    from cosim.fmu.profiles import StoppingCurve

    curve = StoppingCurve(0.5, 400.0)  # seed000_stop_pid's ref_decel and stop_point
    s, v_ref = frame["plant.s"].to_numpy(), frame["controller.v_ref"].to_numpy()
    given = frame["plant.brake_command"].to_numpy()
    command = frame["controller.brake_command"].to_numpy()
    return (all(v_ref[k] == curve.speed(s[k - 1]) for k in range(1, len(frame)))
            and bool(np.all(given[1:] == command[:-1])))


def test_libcosim_delivers_the_command_one_step_later(built_fmus):
    """The Jacobi delay is real: under libcosim every event uses the previous sample's plant
    outputs and the plant gets each command one sample late, which the event master does not
    do (the same check fails on its run, so it tells the two apart)."""
    path = find_scenario("seed000_stop_pid")
    sc = load_scenario(path, {"simulation.stop_time": 10.0})
    sc.record = [*sc.record, "plant.brake_command"]
    event = run_scenario(sc, algorithm="event", plot=False).frame
    theirs = run_libcosim(sc)
    assert len(theirs) == 50 and np.count_nonzero(np.diff(theirs["plant.s"])) == 49
    assert _one_step_late(theirs)
    assert not _one_step_late(event)
    assert _one_step_late(run_scenario(sc, algorithm="jacobi", plot=False).frame)
    assert max(compare_frames(event, theirs, ["plant.v"]).values()) > 1e-4


@pytest.mark.parametrize("path", SCENARIOS, ids=lambda p: p.stem)
def test_fmpy_replays_plant_from_recorded_inputs(path, built_fmus):
    """fmpy.simulate_fmu on the plant alone, fed the commands our master recorded, gives the
    plant outputs of the closed-loop run exactly (sample-and-hold inputs)."""
    sc = load_scenario(path, {"simulation.stop_time": SHORT})
    plant = next(c for c in sc.components.values()
                 if not any(conn.src == c.name for conn in sc.connections
                            if conn.dst == c.name) and c.sample_time is None)
    feeds = {c.dst_var: f"{c.src}.{c.src_var}" for c in sc.connections if c.dst == plant.name}
    outputs = sorted({c.src_var for c in sc.connections if c.src == plant.name})
    sc.record = sorted(set(feeds.values()) | {f"{plant.name}.{o}" for o in outputs})
    h = sc.simulation.base_step or sc.simulation.output_interval
    sc.simulation.output_interval = h  # the replay needs every command change
    frame = run_scenario(sc, algorithm="fixed", plot=False).frame
    replay = simulate_single(plant.fmu_path, frame, feeds, parameters=plant.parameters,
                             outputs=outputs, step=h)
    replay = replay.rename(columns={o: f"{plant.name}.{o}" for o in outputs})
    diffs = compare_frames(frame, replay)
    assert len(replay) == len(frame)
    assert max(diffs.values()) <= 1e-9, diffs
    assert max(np.ptp(frame[f"{plant.name}.{o}"]) for o in outputs) > 0  # something moved


def test_a_parameter_out_of_its_declared_range_is_refused_before_libcosim(built_fmus):
    from cosim.run.scenario import ScenarioError

    with pytest.raises(ScenarioError, match="mass"):
        run_libcosim("seed000_stop_pid", {"plant.mass": -1.0})


def test_libcosim_aborting_its_process_is_an_error_here_not_an_exit(built_fmus):
    """A start value the FMU rejects at initialisation makes libcosim throw through its C API
    (std::terminate, SIGABRT): in the child process that ends only the child, and the error
    carries libcosim's report."""
    from cosim.interop.libcosim import LibcosimError, _isolated
    from cosim.run.scenario import load_scenario

    sc = load_scenario("seed000_stop_pid", {"plant.mass": -1.0})  # past cosim's range check
    with pytest.raises(LibcosimError, match="(?s)ended its process.*fmi2Error"):
        _isolated("_run_libcosim", sc, None, None)
