"""Clocked FMI 3.0 builds of our controllers (``cosim build --fmi 3 --clock``,
:func:`cosim.build.fmi3.clocked`): an input Clock activates the controller's events in place of
``nextEventTime`` (a ``fixed`` periodic Clock for the sampled StopPid, a ``countdown`` Clock for
the self-triggered StopRsmpc).

Run by the master in Event Mode they equal the unclocked FMI 3 builds exactly, sample by
sample: the same Python core computes both, and the Clock ticks where ``nextEventTime`` put
the events (the master schedules a tick at the nearest nanosecond of its double time, the grid
of the controllers' own clocks, :mod:`cosim.fmu.state`). With a recording interval of several
samples the equality holds only if the ticks make the communication points: without them the
master would step over the samples and the controller would run them with held inputs.

Every shipped scenario with a sampled or self-triggered Python controller gives the same
executions and recorded values with the clocked co-simulation builds as with the FMI 3 builds
(slow), which give the FMI 2 builds' (``tests/test_fmi3_scenarios.py``)."""

from __future__ import annotations

import fnmatch
import zipfile
from pathlib import Path
from xml.etree import ElementTree as ET

import pytest

from cosim.build import fmi3
from cosim.build.python import build_stale, catalog
from cosim.interop.compliance import NOTE, Options, check_fmu, format_report, passed
from cosim.run.scenario import load_scenario
from cosim.run.simulate import run_scenario
from tests.test_fmi3_scheduled_builds import (
    SCENARIOS,
    _sampled_controllers,
    assert_same_run,
    clock_of,
)

# clock -> (scenario, controller)
CASES = {"periodic": ("seed000_stop_pid", "StopPid"),
         "countdown": ("seed000_stop_rsmpc", "StopRsmpc")}
TIMING = ["controller.executions", "controller.next_event_time"]
IRREPRODUCIBLE = ("*solve_time*", "*wall_time*", "*cpu_time*")


@pytest.fixture(scope="module")
def clocked_builds(tmp_path_factory) -> dict[str, Path]:
    """clock -> the clocked build of its controller (from its up-to-date FMI 3 build)."""
    specs = catalog()
    build_stale([specs[i] for i in ("BrakeDelayTrain", "StopPid", "StopRsmpc")], fmi_version=3)
    folder = tmp_path_factory.mktemp("clocked")
    return {clock: fmi3.clocked(specs[controller].path_fmi3, clock,
                                folder / clock / f"{controller}.fmu")
            for clock, (_, controller) in CASES.items()}


def _run(name: str, interval: float, controller: Path | None) -> dict:
    sc = load_scenario(name, ["simulation.fmi_version=3",
                              f"simulation.output_interval={interval}"])
    sc.record = [*sc.record, *TIMING]
    ctrl = sc.components["controller"]  # its events from the FMU alone, not [fmus] sample_time
    ctrl.parameters["sample_time"], ctrl.sample_time = ctrl.sample_time, None
    if controller is not None:
        ctrl.fmu_path = controller
    frame = run_scenario(sc, build=False, plot=False).frame
    return {c: frame[c].tolist() for c in frame.columns
            if not any(fnmatch.fnmatch(c, p) for p in IRREPRODUCIBLE)}


@pytest.mark.slow
@pytest.mark.parametrize("clock", sorted(CASES))
@pytest.mark.parametrize("interval", [0.2, 1.0])  # one sample, five samples
def test_clocked_build_equals_the_fmi3_build_sample_by_sample(clocked_builds, clock, interval):
    name, _ = CASES[clock]
    plain, ticked = _run(name, interval, None), _run(name, interval, clocked_builds[clock])
    assert ticked.keys() == plain.keys()
    assert {c: ticked[c] for c in ticked if ticked[c] != plain[c]} == {}
    executions = ticked["controller.executions"]
    assert executions[-1] > executions[0] > 0  # it ran, from its event at the start time


@pytest.mark.parametrize("clock, variability", [("periodic", "fixed"),
                                                ("countdown", "countdown")])
def test_clocked_description_declares_the_input_clock_and_clocks_the_outputs(
        clocked_builds, clock, variability):
    with zipfile.ZipFile(clocked_builds[clock]) as z:
        root = ET.fromstring(z.read("modelDescription.xml"))
    (sample,) = root.iter("Clock")
    assert (sample.get("causality"), sample.get("intervalVariability"),
            sample.get("valueReference")) == ("input", variability, str(fmi3.CLOCK_VR))
    outputs = [v for v in root.find("ModelVariables") if v.get("causality") == "output"]
    assert outputs and all(v.get("clocks") == str(fmi3.CLOCK_VR) for v in outputs)
    clocked = {v.get("valueReference") for v in outputs}
    assert not clocked & {u.get("valueReference") for u in root.iter("InitialUnknown")}


def test_a_model_without_events_or_sample_time_has_no_clocked_build(clocked_builds):
    specs = catalog()
    with zipfile.ZipFile(specs["BrakeDelayTrain"].path_fmi3) as z:
        plant = z.read("modelDescription.xml")
    with pytest.raises(ValueError, match="BrakeDelayTrain: a countdown Clock .* no "
                                         "next_event_time output"):
        fmi3.clocked_description(plant, "countdown")
    with pytest.raises(ValueError, match=r"clock 'sporadic': expected one of"):
        fmi3.clocked_description(plant, "sporadic")


@pytest.mark.slow
@pytest.mark.parametrize("clock", sorted(CASES))
def test_clocked_builds_pass_validate(clocked_builds, clock):
    """``cosim validate`` (FMI 3: the Clock checks included) passes; the Clock ticks at the
    samples: from the start (periodic, shift 0) or from the first countdown the FMU gives
    (its event at the start time is the initial Event Mode's)."""
    path = clocked_builds[clock]
    problems = check_fmu(path, Options(strict=False))
    assert passed(problems), format_report(path, problems)
    (note,) = [p.message for p in problems
               if p.check == "fmi3-clock-calls" and p.severity == NOTE]
    first = "0, 0.2, 0.4" if clock == "periodic" else "0.2, 0.4, 0.6"
    assert f"{fmi3.CLOCK_NAME} at {first}," in note


@pytest.mark.slow
@pytest.mark.parametrize("name", SCENARIOS)
def test_clocked_co_simulation_build_equals_the_fmi3_build_in_every_scenario(name, tmp_path):
    """Every shipped scenario with a sampled or self-triggered Python controller, run on the
    FMI 3 builds: each such controller's clocked co-simulation build (a periodic Clock, or a
    countdown Clock for a self-triggered one) in place of its FMI 3 build gives the same
    executions and the same recorded values bit for bit."""
    controllers = _sampled_controllers(name)
    if not controllers:
        pytest.skip(f"{name}: no sampled or self-triggered Python controller")
    specs = catalog()
    build_stale([specs[c.fmu] for c in load_scenario(name).components.values()
                 if c.fmu in specs], fmi_version=3)
    clocked = {component: fmi3.clocked(specs[identifier].path_fmi3, clock_of(identifier),
                                       tmp_path / component / f"{identifier}.fmu")
               for component, identifier in controllers.items()}
    assert_same_run(name, clocked, ("simulation.fmi_version=3",))
