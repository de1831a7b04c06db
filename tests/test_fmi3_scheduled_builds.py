"""Scheduled Execution builds of our controllers (``cosim build --fmi 3 --clock periodic|countdown
--interface se``, :func:`cosim.build.fmi3.clocked` with ``interface="se"``): the input Clock
``sample`` is the input Clock of the controller's one model partition (FMI 3.0 chap. 5), which
the master (:mod:`cosim.run.master.scheduled`) activates at its ticks.

Every shipped scenario with a sampled or self-triggered Python controller gives, with the SE
build in place of the FMI 2 build, the same executions and the same recorded values bit for
bit: the same Python core computes both, from the same inputs, at the same instants (the
periodic Clock ticks at start + k sample_time, the countdown Clock where the controller's
next event is, both on the nanosecond grid of the controllers' own clocks,
:mod:`cosim.fmu.state`), so no tolerance is needed."""

from __future__ import annotations

import fnmatch
import zipfile
from pathlib import Path
from xml.etree import ElementTree as ET

import pytest
from fmpy.fmi3 import FMU3Slave

from cosim.build import fmi3
from cosim.build.python import ROOT, build_clocked, build_stale, catalog
from cosim.interop.compliance import Options, check_fmu, format_report, passed
from cosim.run.master import SimulationError
from cosim.run.master.core import Master
from cosim.run.scenario import load_scenario, scenario_files
from cosim.run.simulate import run_scenario
from tests.cli_inproc import cosim_inproc

TIMING = ("executions", "next_event_time")
IRREPRODUCIBLE = ("*solve_time*", "*wall_time*", "*cpu_time*")
# controllers whose events are not one sample apart (their cores hold a command M samples):
# a countdown Clock; every other sampled controller takes the periodic Clock, whose front
# refuses an event more than one interval away, so a missing entry here fails loudly
SELF_TRIGGERED = {"StopRsmpc"}
SCENARIOS = list(scenario_files())


def _sampled_controllers(name: str) -> dict[str, str]:
    """Component -> FMU identifier of the scenario's Python controllers with events (an output
    ``next_event_time``, :data:`cosim.fmu.slave.CONTROLLER_TIMING_VARS`)."""
    specs = catalog()
    out = {}
    for comp in load_scenario(name).components.values():
        spec = specs.get(comp.fmu)
        if spec is not None and any(v.name == fmi3.EVENT_TIME_OUTPUT
                                    for v in spec.load().declared_variables()):
            out[comp.name] = comp.fmu
    return out


def clock_of(identifier: str) -> str:
    return "countdown" if identifier in SELF_TRIGGERED else "periodic"


def _run(name: str, scheduled: dict[str, Path], overrides: tuple[str, ...] = ()
         ) -> tuple[dict, dict]:
    """The scenario's recorded values (irreproducible timings left out) and executions, with
    ``overrides`` and the components of ``scheduled`` on those builds (SE or clocked; their
    events from the FMU alone, not [fmus] sample_time)."""
    sc = load_scenario(name, list(overrides))
    sc.record = [*sc.record, *(f"{c}.{v}" for c in _sampled_controllers(name) for v in TIMING)]
    for component, path in scheduled.items():
        comp = sc.components[component]
        comp.parameters["sample_time"], comp.sample_time = comp.sample_time, None
        comp.fmu_path = path
    result = run_scenario(sc, build=False, plot=False)
    frame = result.frame
    return ({c: frame[c].tolist() for c in frame.columns
             if not any(fnmatch.fnmatch(c, p) for p in IRREPRODUCIBLE)}, result.executions)


@pytest.mark.slow
@pytest.mark.parametrize("name", SCENARIOS)
def test_scheduled_build_equals_the_fmi2_build(name):
    controllers = _sampled_controllers(name)
    if not controllers:
        pytest.skip(f"{name}: no sampled or self-triggered Python controller")
    specs = catalog()
    build_stale([specs[c.fmu] for c in load_scenario(name).components.values()
                 if c.fmu in specs])
    scheduled = {component: build_clocked(specs[identifier], clock_of(identifier), "se")
                 for component, identifier in controllers.items()}
    assert_same_run(name, scheduled)


def assert_same_run(name: str, builds: dict[str, Path], overrides: tuple[str, ...] = ()
                    ) -> None:
    """The scenario with the components of ``builds`` on those builds equals it without them
    (``overrides`` on both): the same executions and recorded values bit for bit, and each of
    those components ran from its event at the start time."""
    plain, plain_executions = _run(name, {}, overrides)
    ticked, ticked_executions = _run(name, builds, overrides)
    assert ticked_executions == plain_executions
    assert ticked.keys() == plain.keys()
    assert {c: ticked[c] for c in ticked if ticked[c] != plain[c]} == {}
    for component in builds:
        executions = ticked[f"{component}.executions"]
        assert executions[-1] > executions[0] > 0


@pytest.fixture(scope="module")
def scheduled_builds(tmp_path_factory) -> dict[str, Path]:
    """clock -> the SE build of a controller (StopPid periodic, StopRsmpc countdown)."""
    specs = catalog()
    build_stale([specs["StopPid"], specs["StopRsmpc"]], fmi_version=3)
    folder = tmp_path_factory.mktemp("scheduled")
    return {clock: fmi3.clocked(specs[ident].path_fmi3, clock, folder / clock / f"{ident}.fmu",
                                "se")
            for clock, ident in (("periodic", "StopPid"), ("countdown", "StopRsmpc"))}


@pytest.mark.parametrize("clock", ["periodic", "countdown"])
def test_scheduled_description(scheduled_builds, clock):
    """A ScheduledExecution element in place of CoSimulation with the fmi3InterfaceType
    attributes only (FMI 3.0 sec. 2.4.2); the input Clock declares priority 0 (sec. 2.4.4:
    required in Scheduled Execution); the outputs are clocked by it."""
    with zipfile.ZipFile(scheduled_builds[clock]) as z:
        root = ET.fromstring(z.read("modelDescription.xml"))
    assert root.find("CoSimulation") is None
    (se,) = root.iter("ScheduledExecution")
    assert set(se.attrib) <= {"modelIdentifier", "needsExecutionTool",
                              "canBeInstantiatedOnlyOncePerProcess"}
    assert "modelIdentifier" in se.attrib
    (sample,) = root.iter("Clock")
    assert (sample.get("causality"), sample.get("intervalVariability"),
            sample.get("priority")) == ("input", fmi3.CLOCK_VARIABILITY[clock], "0")
    outputs = [v for v in root.find("ModelVariables") if v.get("causality") == "output"]
    assert outputs and all(v.get("clocks") == str(fmi3.CLOCK_VR) for v in outputs)


def test_an_unknown_interface_is_refused(scheduled_builds):
    with zipfile.ZipFile(catalog()["StopPid"].path_fmi3) as z:
        xml = z.read("modelDescription.xml")
    with pytest.raises(ValueError, match=r"interface 'me': expected one of \['cs', 'se'\]"):
        fmi3.clocked_description(xml, "periodic", "me")


def test_a_scheduled_build_refuses_co_simulation(scheduled_builds, tmp_path):
    """fmi3InstantiateCoSimulation of an SE build returns NULL with the reason logged."""
    path = scheduled_builds["periodic"]
    folder = tmp_path / "x"
    with zipfile.ZipFile(path) as z:
        z.extractall(folder)
        md = ET.fromstring(z.read("modelDescription.xml"))
    messages = []
    slave = FMU3Slave(guid=md.get("instantiationToken"), unzipDirectory=str(folder),
                      modelIdentifier=md.find("ScheduledExecution").get("modelIdentifier"),
                      instanceName="c")
    with pytest.raises(Exception, match="Failed to instantiate"):
        slave.instantiate(logMessage=lambda env, status, category, message:
                          messages.append(message.decode()))
    assert any("supports Scheduled Execution only" in m for m in messages), messages
    slave.freeLibrary()


def test_the_master_runs_a_scheduled_build_only_with_the_event_algorithm(scheduled_builds):
    sc = load_scenario("seed000_stop_pid", ["simulation.algorithm=fixed",
                                            "simulation.stop_time=1"])
    comp = sc.components["controller"]
    comp.parameters["sample_time"], comp.sample_time = comp.sample_time, None
    comp.fmu_path = scheduled_builds["periodic"]
    build_stale([catalog()["BrakeDelayTrain"]])
    with pytest.raises(SimulationError, match=r'Scheduled Execution.*algorithm = "event"'):
        Master(sc).run()


@pytest.mark.slow
@pytest.mark.parametrize("clock", ["periodic", "countdown"])
def test_scheduled_builds_pass_validate(scheduled_builds, clock):
    """``cosim validate`` (FMI 3: its Scheduled Execution checks) passes; the partition runs
    at the samples from the start time (the countdown Clock's first interval, asked in
    Initialization Mode, is 0: FMI 3.0 sec. 2.2.8.2, countdown Clock)."""
    path = scheduled_builds[clock]
    problems = check_fmu(path, Options(strict=False))
    assert passed(problems), format_report(path, problems)
    (note,) = [p.message for p in problems if p.check == "fmi3-scheduled-execution"]
    assert f"{fmi3.CLOCK_NAME} at 0, 0.2, 0.4," in note


@pytest.mark.slow
def test_mixed_scenario_scheduled_co_simulation_and_fmi2():
    """scenarios/mixed/seed000_stop_pid_scheduled.toml: the SE StopPid drives the FMI 3
    co-simulation train, an FMI 2 StopPid reads the same measurements in shadow. The two
    controllers give the same command at every output point (bit for bit: the same core, the
    same inputs at the same instants), and the loop is seed000_stop_pid's, whose three FMUs
    are all FMI 2: the same train positions and speeds."""
    specs = catalog()
    build_stale([specs["BrakeDelayTrain"], specs["StopPid"]], fmi_version=3)
    build_stale([specs["BrakeDelayTrain"], specs["StopPid"]])
    build_clocked(specs["StopPid"], "periodic", "se")
    mixed = run_scenario(load_scenario(ROOT / "scenarios" / "mixed" /
                                       "seed000_stop_pid_scheduled.toml"),
                         build=False, plot=False)
    plain = run_scenario(load_scenario("seed000_stop_pid"), build=False, plot=False).frame
    frame = mixed.frame
    assert mixed.executions["controller"] == mixed.executions["shadow"] > 1
    assert frame["controller.brake_command"].tolist() == frame["shadow.brake_command"].tolist()
    assert frame["controller.executions"].tolist() == frame["shadow.executions"].tolist()
    for column in ("time", "plant.s", "plant.v", "controller.brake_command"):
        assert frame[column].tolist() == plain[column].tolist(), column


@pytest.mark.parametrize("args, message", [
    (["--interface", "se"], "--interface se: an interface of a clocked build: give --clock too"),
    (["--clock", "periodic", "--interface", "me"], "--interface 'me': expected one of cs, se"),
])
def test_cli_interface_errors(args, message):
    done = cosim_inproc("build", "StopPid", "--fmi", "3", *args)
    assert done.exit_code != 0
    assert message in " ".join((done.stdout + done.stderr).split())


def test_a_binary_refusing_the_event_mode_it_declares_is_named(tmp_path):
    """The FMI 3 train's modelDescription edited to declare hasEventMode = true: the event
    algorithm asks for Event Mode, the front refuses it (it has no events); the error names
    the call, its arguments, the FMU's reason and the way out."""
    spec = catalog()["BrakeDelayTrain"]
    build_stale([spec, catalog()["StopPid"]], fmi_version=3)
    fmu = tmp_path / "EventTrain.fmu"
    with zipfile.ZipFile(spec.path_fmi3) as source, zipfile.ZipFile(fmu, "w") as out:
        for item in source.infolist():
            data = source.read(item)
            if item.filename == "modelDescription.xml":
                assert b'hasEventMode="true"' not in data
                data = data.replace(b"<CoSimulation ", b'<CoSimulation hasEventMode="true" ')
            out.writestr(item, data)
    sc = load_scenario("seed000_stop_pid", ["simulation.fmi_version=3",
                                            "simulation.stop_time=1"])
    sc.components["plant"].fmu_path = fmu
    with pytest.raises(SimulationError) as err:
        Master(sc).run()
    text = str(err.value)
    assert "plant (" in text and "EventTrain.fmu): fmi3InstantiateCoSimulation(eventModeUsed " \
        "= true, earlyReturnAllowed = true) returned NULL" in text
    assert "but this FMU declares hasEventMode = false" in text  # the front's reason
    assert 'declares hasEventMode = true' in text and 'algorithm = "fixed"' in text
