"""FMI 3.0 builds of our FMUs (``cosim build --fmi 3``, :mod:`cosim.build.fmi3`): valid FMI 3.0
co-simulation FMUs with the FMI 2 twin's variables, run by fmpy alone in Event Mode, giving the
FMI 2 twin's outputs bit for bit (the same Python core computes both: the front only forwards
and converts, it does no arithmetic on values), announcing their events as ``nextEventTime`` and
executing each exactly once."""

from __future__ import annotations

import fnmatch
import math
import shutil
import zipfile
from pathlib import Path
from xml.etree import ElementTree as ET

import pytest
from fmpy import extract, read_model_description, simulate_fmu
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import FMU2Slave
from fmpy.fmi3 import FMU3Slave, fmi3Error

from cosim.build.fmi3 import TIME_VR, model_description
from cosim.build.python import catalog

SPECS = catalog()
IDENTIFIERS = sorted(SPECS)
# outputs that measure wall-clock time: irreproducible between any two runs
IRREPRODUCIBLE = ("*wall_time*", "*solve_time*", "*cpu_time*")


@pytest.fixture(scope="module")
def fmi3_builds(built_fmus_fmi3):
    return {i: s.path_fmi3 for i, s in built_fmus_fmi3.items()}


def _is_controller(identifier: str) -> bool:
    md = read_model_description(str(SPECS[identifier].path))
    return any(v.name == "next_event_time" for v in md.modelVariables)


CONTROLLERS = [i for i in IDENTIFIERS if SPECS[i].module.startswith("controllers.")]
PLANTS = [i for i in IDENTIFIERS if SPECS[i].module.startswith("plants.")]


def test_catalog_splits_into_controllers_and_plants():
    assert set(CONTROLLERS) | set(PLANTS) == set(IDENTIFIERS) and CONTROLLERS and PLANTS


@pytest.mark.parametrize("identifier", IDENTIFIERS)
def test_fmi3_model_description_is_the_fmi2_one(identifier, fmi3_builds):
    """The FMI 3 build declares the FMI 2 twin's variables, dependencies and binaries (fmpy's
    validation of it: check ``fmi3-validation``, tests/compliance/test_compliance_fmi3.py)."""
    path3 = fmi3_builds[identifier]
    md2 = read_model_description(str(SPECS[identifier].path))
    md3 = read_model_description(str(path3))
    assert md3.fmiVersion == "3.0"
    assert md3.coSimulation.modelIdentifier == identifier
    assert md3.coSimulation.canHandleVariableCommunicationStepSize
    v2 = {v.name: v for v in md2.modelVariables}
    v3 = {v.name: v for v in md3.modelVariables if v.causality != "independent"}
    assert list(v2) == list(v3)
    for name, a in v2.items():
        b = v3[name]
        assert (b.valueReference, b.causality, b.variability, b.unit, b.start, b.min, b.max) == (
            a.valueReference, a.causality, a.variability, a.unit, a.start, a.min, a.max), name
        assert b.type == {"Real": "Float64", "Integer": "Int32"}.get(a.type, a.type)
    (time,) = [v for v in md3.modelVariables if v.causality == "independent"]
    assert (time.name, time.valueReference, time.unit) == ("time", TIME_VR, "s")
    deps2 = {o.variable.name: sorted(d.name for d in o.dependencies or []) for o in md2.outputs}
    deps3 = {o.variable.name: sorted(d.name for d in o.dependencies or []) for o in md3.outputs}
    assert deps2 == deps3
    controller = identifier in CONTROLLERS
    assert bool(md3.coSimulation.hasEventMode) == controller == _is_controller(identifier)
    with zipfile.ZipFile(path3) as z:
        names = set(z.namelist())
    for suffix in ("", "_fmi2", "_fmi2_pythonfmu"):
        assert f"binaries/x86_64-linux/{identifier}{suffix}.so" in names
    assert not any(n.startswith(("binaries/linux64", "binaries/win64")) for n in names)
    assert any(n.startswith("resources/atocosim_bundle/") for n in names)


def test_instantiation_token_is_the_fmi2_guid(built_fmus):
    with zipfile.ZipFile(built_fmus["StopPid"].path) as z:
        fmi2_xml = z.read("modelDescription.xml")
    md3, event_vr = model_description(fmi2_xml)
    root2, root3 = ET.fromstring(fmi2_xml), ET.fromstring(md3)
    assert root3.get("instantiationToken") == root2.get("guid")
    names = {v.get("name"): v.get("valueReference") for v in root2.find("ModelVariables")}
    assert event_vr == int(names["next_event_time"])


def test_model_description_rejects_a_non_fmi2_description():
    with pytest.raises(ValueError, match="not an FMI 2.0"):
        model_description(b'<fmiModelDescription fmiVersion="3.0"/>')


def _sample_time(md) -> float:
    return next(float(v.start) for v in md.modelVariables if v.name == "sample_time")


@pytest.mark.parametrize("early_return", [False, True])
@pytest.mark.parametrize("identifier", CONTROLLERS)
def test_fmpy_simulates_each_fmi3_controller_alone_in_event_mode(identifier, early_return,
                                                                 fmi3_builds):
    """fmpy.simulate_fmu(use_event_mode=True) runs every controller alone: output points on
    its sample grid, or (early return allowed) at 2.5 sample times, where the FMU returns early
    at each event it announced."""
    path = fmi3_builds[identifier]
    md = read_model_description(str(path))
    T = _sample_time(md)
    interval = 2.5 * T if early_return else T
    result = simulate_fmu(str(path), use_event_mode=True, early_return_allowed=early_return,
                          start_time=0.0, stop_time=6 * T, output_interval=interval,
                          output=["executions", "next_event_time"])
    assert result["time"][-1] == pytest.approx(6 * T)
    executions = result["executions"]
    assert executions[0] >= 1 and all(b >= a for a, b in zip(executions, executions[1:]))
    assert all(n > t or math.isclose(n, t) for t, n in zip(result["time"],
                                                           result["next_event_time"]))


def _input_signal(md, k: int) -> dict:
    """Deterministic inputs at step k: ``start + a sin(0.7 k + vr)`` inside [min, max] (the
    same in both builds: equal value references)."""
    values = {}
    for v in md.modelVariables:
        if v.causality != "input" or v.type not in ("Real", "Float64"):
            continue
        start = float(v.start or 0.0)
        lo = float(v.min) if v.min is not None else None
        hi = float(v.max) if v.max is not None else None
        amplitude = 0.1 * (abs(start) + 1.0)
        if lo is not None and hi is not None:
            amplitude = min(amplitude, 0.25 * (hi - lo))
        x = start + amplitude * math.sin(0.7 * k + v.valueReference)
        values[v.valueReference] = min(max(x, lo if lo is not None else x),
                                       hi if hi is not None else x)
    return values


def _outputs(md):
    return [v for v in md.modelVariables if v.causality == "output"
            and not any(fnmatch.fnmatch(v.name, p) for p in IRREPRODUCIBLE)]


def _read(fmu, outs, fmi3: bool) -> list:
    got = []
    for v in outs:
        if v.type in ("Real", "Float64"):
            got += (fmu.getFloat64 if fmi3 else fmu.getReal)([v.valueReference])
        elif v.type in ("Integer", "Int32"):
            got += (fmu.getInt32 if fmi3 else fmu.getInteger)([v.valueReference])
        elif v.type == "Boolean":
            got += [bool(b) for b in fmu.getBoolean([v.valueReference])]
        else:
            got += [s.decode() if isinstance(s, bytes) else s
                    for s in fmu.getString([v.valueReference])]
    return got


def _run_fmi2(path: Path, tmp: Path, n: int, h: float) -> list:
    md = read_model_description(str(path))
    unzip = extract(str(path), unzipdir=str(tmp / "fmi2"))
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzip,
                    modelIdentifier=md.coSimulation.modelIdentifier, instanceName="twin2")
    fmu.instantiate()
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    outs, rows, t = _outputs(md), [], 0.0
    for k in range(n):
        inputs = _input_signal(md, k)
        if inputs:
            fmu.setReal(list(inputs), list(inputs.values()))
        rows.append(_read(fmu, outs, fmi3=False))
        fmu.doStep(t, h)
        t = (k + 1) * h
    rows.append(_read(fmu, outs, fmi3=False))
    fmu.terminate()
    fmu.freeInstance()
    return rows


def _run_fmi3(path: Path, tmp: Path, n: int, h: float, event_mode: bool) -> list:
    md = read_model_description(str(path))
    unzip = extract(str(path), unzipdir=str(tmp / "fmi3"))
    fmu = FMU3Slave(guid=md.guid, unzipDirectory=unzip,
                    modelIdentifier=md.coSimulation.modelIdentifier, instanceName="twin3")
    fmu.instantiate(eventModeUsed=event_mode)
    fmu.enterInitializationMode(startTime=0.0)
    fmu.exitInitializationMode()
    outs, rows, t, in_event = _outputs(md), [], 0.0, event_mode
    for k in range(n):
        inputs = _input_signal(md, k)
        if inputs:
            fmu.setFloat64(list(inputs), list(inputs.values()))
        rows.append(_read(fmu, outs, fmi3=True))
        if in_event:
            needs_update, terminate, _, _, defined, next_time = fmu.updateDiscreteStates()
            assert not needs_update and not terminate and defined and next_time > t
            fmu.enterStepMode()
        event, terminate, early, last = fmu.doStep(t, h)
        assert not terminate and not early and last == pytest.approx(t + h, abs=1e-12)
        t = (k + 1) * h
        in_event = event_mode and event
        if in_event:
            fmu.enterEventMode()
    rows.append(_read(fmu, outs, fmi3=True))
    assert fmu.getFloat64([TIME_VR]) == [t]
    fmu.terminate()
    fmu.freeInstance()
    return rows


@pytest.mark.parametrize("identifier", IDENTIFIERS)
def test_fmi3_build_gives_the_fmi2_outputs_bit_for_bit(identifier, fmi3_builds, tmp_path):
    """The same inputs into both builds, stepped on the controller's sample grid (plants: the
    default step), give identical outputs at every communication point (==, not a
    tolerance: the same Python core computes both)."""
    md = read_model_description(str(SPECS[identifier].path))
    controller = identifier in CONTROLLERS
    h = _sample_time(md) if controller else float(md.defaultExperiment.stepSize)
    rows2 = _run_fmi2(SPECS[identifier].path, tmp_path, 12, h)
    rows3 = _run_fmi3(fmi3_builds[identifier], tmp_path, 12, h, event_mode=controller)
    assert rows3 == rows2


def _instance(path: Path, tmp: Path, name: str, **kw) -> tuple[FMU3Slave, object]:
    md = read_model_description(str(path))
    unzip = extract(str(path), unzipdir=str(tmp / name))
    fmu = FMU3Slave(guid=md.guid, unzipDirectory=unzip,
                    modelIdentifier=md.coSimulation.modelIdentifier, instanceName=name)
    fmu.instantiate(**kw)
    return fmu, md


def _vr(md, name: str) -> int:
    return next(v.valueReference for v in md.modelVariables if v.name == name)


@pytest.mark.parametrize("identifier", CONTROLLERS)
def test_each_announced_event_executes_exactly_once(identifier, fmi3_builds, tmp_path):
    """Stepping from event to announced event (nextEventTime), with steps of 3.5 sample times
    and early return: the FMU returns early exactly at each announced time, runs one event
    there (executions + 1), and the hold between events is a whole number of samples (more
    than one for a self-triggered controller)."""
    fmu, md = _instance(fmi3_builds[identifier], tmp_path, "events", eventModeUsed=True,
                        earlyReturnAllowed=True)
    T = _sample_time(md)
    executions, next_event = _vr(md, "executions"), _vr(md, "next_event_time")
    fmu.enterInitializationMode(startTime=0.0)
    fmu.exitInitializationMode()
    t, count = 0.0, None
    for _ in range(8):
        *_, defined, announced = fmu.updateDiscreteStates()
        assert defined and announced > t
        assert fmu.getFloat64([next_event]) == [announced]
        # the event of this instant, computed from its inputs (committed by the next doStep)
        done = fmu.getInt32([executions])[0]
        assert count is None or done == count + 1  # one event at this instant
        count = done
        holds = (announced - t) / T
        assert holds == pytest.approx(round(holds), abs=1e-6) and round(holds) >= 1
        fmu.enterStepMode()
        event, terminate, early, last = fmu.doStep(t, 3.5 * T)
        expected_early = announced < t + 3.5 * T - 1e-9
        assert early == expected_early and not terminate
        assert last == (announced if expected_early else pytest.approx(t + 3.5 * T))
        if not expected_early:  # the next step must end on the event: shorten it
            pytest.fail(f"{identifier} holds {holds} samples > 3.5; use a longer step")
        assert event
        t = last
        fmu.enterEventMode()
    fmu.terminate()
    fmu.freeInstance()


def _messages():
    got = []

    def logger(env, status, category, message):
        got.append((status, message.decode()))

    return got, logger


def test_front_rejects_calls_out_of_sequence_and_logs_with_logging_off(fmi3_builds, tmp_path):
    got, logger = _messages()
    fmu, md = _instance(fmi3_builds["StopPid"], tmp_path, "seq", loggingOn=False,
                        logMessage=logger)
    with pytest.raises(FMICallException) as err:
        fmu.doStep(0.0, 0.1)
    assert err.value.status == fmi3Error
    assert any("fmi3DoStep is not allowed in state Instantiated" in m for _, m in got)
    fmu.enterInitializationMode(startTime=0.0)
    fmu.exitInitializationMode()  # eventModeUsed = false: Step Mode
    with pytest.raises(FMICallException):
        fmu.enterEventMode()
    assert any("eventModeUsed = false" in m for _, m in got)
    with pytest.raises(FMICallException):
        fmu.doStep(0.0, -1.0)
    assert any("step size must be positive" in m for _, m in got)
    with pytest.raises(FMICallException):
        fmu.setFloat64([TIME_VR], [1.0])
    fmu.doStep(0.0, _sample_time(md))
    fmu.terminate()
    with pytest.raises(FMICallException):
        fmu.doStep(0.1, 0.1)
    assert any("not allowed in state Terminated" in m for _, m in got)
    fmu.reset()  # back to Instantiated: a full rerun works
    fmu.enterInitializationMode(startTime=0.0)
    fmu.exitInitializationMode()
    fmu.doStep(0.0, _sample_time(md))
    fmu.terminate()
    fmu.freeInstance()


def test_plant_refuses_event_mode_with_a_message(fmi3_builds, tmp_path):
    got, logger = _messages()
    with pytest.raises(Exception, match="[Ff]ailed to instantiate"):  # noqa: B017
        _instance(fmi3_builds[PLANTS[0]], tmp_path, "plant",
                  eventModeUsed=True, logMessage=logger)
    assert any("hasEventMode = false" in m for _, m in got)


def test_serialized_state_restores_time_and_outputs(fmi3_builds, tmp_path):
    fmu, md = _instance(fmi3_builds["StopPid"], tmp_path, "state")
    T = _sample_time(md)
    outs = _outputs(md)
    fmu.enterInitializationMode(startTime=0.0)
    fmu.exitInitializationMode()
    fmu.doStep(0.0, T)
    state = fmu.serializeFMUState(fmu.getFMUState())
    fmu.doStep(T, T)
    after = (_read(fmu, outs, fmi3=True), fmu.getFloat64([TIME_VR]))
    restored = fmu.deserializeFMUState(state)
    fmu.setFMUState(restored)
    assert fmu.getFloat64([TIME_VR]) == [T]
    fmu.doStep(T, T)
    assert (_read(fmu, outs, fmi3=True), fmu.getFloat64([TIME_VR])) == after
    fmu.freeFMUState(restored)
    fmu.terminate()
    fmu.freeInstance()


def test_fmi3_build_is_self_contained(fmi3_builds, tmp_path):
    """Copied elsewhere (no project tree next to it) it still runs: the bundle and the three
    binaries travel in the zip."""
    copy = tmp_path / "elsewhere" / "StopPid.fmu"
    copy.parent.mkdir()
    shutil.copy2(fmi3_builds["StopPid"], copy)
    md = ET.fromstring(zipfile.ZipFile(copy).read("modelDescription.xml"))
    assert md.get("fmiVersion") == "3.0"
    result = simulate_fmu(str(copy), use_event_mode=True, stop_time=1.0, output_interval=0.2,
                          output=["executions"])
    assert list(result["executions"])[-1] >= 5


def _long_step(fmu, t: float, h: float) -> str:
    """'ok' or 'refused' for one doStep of ``h`` from ``t``."""
    try:
        fmu.doStep(t, h)
    except FMICallException:
        return "refused"
    return "ok"


@pytest.mark.parametrize("identifier", ["StopPid", "StopRsmpc"])
def test_without_early_return_a_long_step_does_what_the_fmi2_twin_does(identifier, fmi3_builds,
                                                                      tmp_path):
    """A step over several announced events with early return not allowed is forwarded as it
    is: the FMI 3 build then refuses it or computes it exactly as the FMI 2 twin does."""
    md2 = read_model_description(str(SPECS[identifier].path))
    h = 3.5 * _sample_time(md2)
    outs = _outputs(md2)
    unzip = extract(str(SPECS[identifier].path), unzipdir=str(tmp_path / "two"))
    two = FMU2Slave(guid=md2.guid, unzipDirectory=unzip, modelIdentifier=identifier,
                    instanceName="two")
    two.instantiate()
    two.setupExperiment(startTime=0.0)
    two.enterInitializationMode()
    two.exitInitializationMode()
    three, _ = _instance(fmi3_builds[identifier], tmp_path, "three", eventModeUsed=True)
    three.enterInitializationMode(startTime=0.0)
    three.exitInitializationMode()
    three.updateDiscreteStates()
    three.enterStepMode()
    assert _read(three, outs, fmi3=True) == _read(two, outs, fmi3=False)
    outcome2, outcome3 = _long_step(two, 0.0, h), _long_step(three, 0.0, h)
    assert outcome3 == outcome2
    if outcome2 == "ok":
        assert _read(three, outs, fmi3=True) == _read(two, outs, fmi3=False)
    for fmu in (two, three):
        fmu.freeInstance()


def _closed_loop(plant_path: Path, ctrl_path: Path, tmp: Path, fmi3: bool, n_events: int
                 ) -> list[tuple]:
    """The BrakeDelayTrain plant and the self-triggered StopRsmpc, communicating only at the
    controller's announced events (FMI 3: nextEventTime in Event Mode; FMI 2: the
    ``next_event_time`` output); per event (t, hold in samples, executions, u, v, s)."""
    made = []
    for name, path in (("plant", plant_path), ("ctrl", ctrl_path)):
        md = read_model_description(str(path))
        unzip = extract(str(path), unzipdir=str(tmp / f"{name}{int(fmi3)}"))
        cls = FMU3Slave if fmi3 else FMU2Slave
        fmu = cls(guid=md.guid, unzipDirectory=unzip,
                  modelIdentifier=md.coSimulation.modelIdentifier, instanceName=name)
        if fmi3:
            fmu.instantiate(eventModeUsed=name == "ctrl")
            fmu.enterInitializationMode(startTime=0.0)
        else:
            fmu.instantiate()
            fmu.setupExperiment(startTime=0.0)
            fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        made.append((fmu, {v.name: v.valueReference for v in md.modelVariables}, md))
    (plant, pv, _), (ctrl, cv, cmd) = made
    get, set_ = ("getFloat64", "setFloat64") if fmi3 else ("getReal", "setReal")
    get_int = ctrl.getInt32 if fmi3 else ctrl.getInteger
    T = _sample_time(cmd)
    rows, t = [], 0.0
    for _ in range(n_events):
        for name in ("v", "s", "a_c"):
            getattr(ctrl, set_)([cv[name]], getattr(plant, get)([pv[name]]))
        u = getattr(ctrl, get)([cv["brake_command"]])[0]
        if fmi3:
            *_, defined, announced = ctrl.updateDiscreteStates()
            assert defined
            ctrl.enterStepMode()
        else:
            announced = ctrl.getReal([cv["next_event_time"]])[0]
        rows.append((t, round((announced - t) / T), get_int([cv["executions"]])[0], u,
                     *getattr(plant, get)([pv["v"], pv["s"]])))
        getattr(plant, set_)([pv["brake_command"]], [u])
        plant.doStep(t, announced - t)
        if fmi3:
            event, _, early, _ = ctrl.doStep(t, announced - t)
            assert event and not early
            ctrl.enterEventMode()
        else:
            ctrl.doStep(t, announced - t)
        t = announced
    for fmu, _, _ in made:
        fmu.terminate()
        fmu.freeInstance()
    return rows


def test_self_triggered_controller_closed_loop_fmi3_equals_fmi2(built_fmus_fmi3, tmp_path):
    """Closed loop stepped from announced event to announced event: each event executes the
    controller exactly once (executions 1, 2, 3, ...), it holds more than one sample at some
    events (self-triggered), and the FMI 3 pair gives the FMI 2 pair's numbers bit for bit."""
    specs = built_fmus_fmi3
    n = 60
    rows3 = _closed_loop(specs["BrakeDelayTrain"].path_fmi3, specs["StopRsmpc"].path_fmi3,
                         tmp_path, True, n)
    rows2 = _closed_loop(specs["BrakeDelayTrain"].path, specs["StopRsmpc"].path, tmp_path,
                         False, n)
    assert [r[2] for r in rows3] == list(range(1, n + 1))
    assert max(r[1] for r in rows3) > 1 and min(r[1] for r in rows3) >= 1
    assert rows3 == rows2
