"""Our sampled controllers under any master (issue 13): a doStep passing over a sample instant
is refused with a clear message (no event dropped silently), a doStep must continue from the
controller's own time, outputs at an event follow the inputs set last (no latch on the first
read) and doStep commits the event of the inputs it was given; the scenario check rejects
fixed-step timing that would skip events or misplace output points."""

from __future__ import annotations

import pytest
from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import FMU2Slave

from cosim.run.master import logging_callbacks
from cosim.run.scenario import ScenarioError
from cosim.run.simulate import run_scenario

T = 0.2  # StopPid's sample time in the test


@pytest.fixture(scope="module")
def stop_pid(built_fmus, tmp_path_factory):
    path = built_fmus["StopPid"].path
    return read_model_description(str(path)), extract(
        str(path), unzipdir=str(tmp_path_factory.mktemp("stoppid")))


class Instance:
    """fmpy FMU2Slave of StopPid with its log kept."""

    def __init__(self, stop_pid, name: str = "pid", strict: bool = False,
                 logging: bool = True) -> None:
        md, unzipdir = stop_pid
        self.vr = {v.name: v.valueReference for v in md.modelVariables}
        self.messages: list[str] = []
        self._cb = logging_callbacks(lambda status, text: self.messages.append(text))
        self.fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzipdir, instanceName=name,
                             modelIdentifier=md.coSimulation.modelIdentifier)
        self.fmu.instantiate(callbacks=self._cb, loggingOn=logging)
        self.fmu.setupExperiment(startTime=0.0)
        self.fmu.setReal([self.vr["sample_time"]], [T])
        self.fmu.setBoolean([self.vr["strict_steps"]], [strict])
        self.fmu.enterInitializationMode()
        self.fmu.exitInitializationMode()

    def set(self, **values: float) -> None:
        for name, value in values.items():
            self.fmu.setReal([self.vr[name]], [value])

    def get(self, *names: str) -> list[float]:
        return self.fmu.getReal([self.vr[n] for n in names])

    def free(self) -> None:
        self.fmu.freeInstance()


@pytest.mark.parametrize("logging", [True, False])
def test_step_over_a_sample_instant_is_refused_when_strict(stop_pid, logging):
    """strict_steps: the refusal, and its reason logged even with logging off (fmpy's
    default), as the Reference FMUs log their errors."""
    pid = Instance(stop_pid, strict=True, logging=logging)
    pid.set(v=20.0, s=0.0)
    with pytest.raises(FMICallException):
        pid.fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=1.0)
    assert any("passes over this controller's event at t=0.2 s" in m for m in pid.messages)
    pid.free()


def test_events_inside_a_long_step_run_with_the_inputs_held(stop_pid):
    """A 1 s step over a 0.2 s controller executes its 5 events (t = 0, 0.2, ..., 0.8) with
    the inputs of the step's start, as five 0.2 s steps with the same inputs do; said once."""
    long, short = Instance(stop_pid, "long"), Instance(stop_pid, "short")
    for pid in (long, short):
        pid.set(v=20.0, s=0.0)
    for k in range(2):
        long.fmu.doStep(currentCommunicationPoint=float(k), communicationStepSize=1.0)
        for j in range(5):
            short.fmu.doStep(currentCommunicationPoint=round(k + j * T, 9),
                             communicationStepSize=T)
    names = ("brake_command", "next_event_time")
    assert long.get(*names) == short.get(*names)
    count = [pid.fmu.getInteger([pid.vr["executions"]]) for pid in (long, short)]
    assert count[0] == count[1] == [11]  # 10 committed, the one at t = 2 s shown
    held = [m for m in long.messages if "executed with the inputs held" in m]
    assert len(held) == 1 and not any("inputs held" in m for m in short.messages)
    long.free()
    short.free()


def test_a_step_shorter_than_the_sample_that_passes_over_an_event_says_so(stop_pid):
    """A 0.12 s step from t = 0.1 s passes over the 0.2 s controller's event at t = 0.2 s: the
    warning names that event and does not call the step longer than the sample."""
    pid = Instance(stop_pid)
    pid.set(v=20.0, s=0.0)
    pid.fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=0.1)
    pid.fmu.doStep(currentCommunicationPoint=0.1, communicationStepSize=0.12)
    held = [m for m in pid.messages if "executed with the inputs held" in m]
    assert len(held) == 1 and "passes over this controller's event at t=0.2 s" in held[0]
    assert "longer than" not in held[0]
    pid.free()


def test_step_must_continue_from_own_time(stop_pid):
    pid = Instance(stop_pid)
    pid.set(v=20.0, s=0.0)
    pid.fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=T)
    with pytest.raises(FMICallException):
        pid.fmu.doStep(currentCommunicationPoint=0.4, communicationStepSize=T)
    assert any("but this controller is at t=0.2 s" in m for m in pid.messages)
    pid.free()


def test_outputs_follow_inputs_set_again_at_the_same_instant(stop_pid):
    """Read with (v=20, s=0), set (v=18, s=50) at the same instant and read again: the second
    read equals a fresh instance given only the second inputs; doStep commits those."""
    a, b = Instance(stop_pid, "a"), Instance(stop_pid, "b")
    a.set(v=20.0, s=0.0)
    first = a.get("brake_command", "v_ref", "speed_error")
    a.set(v=18.0, s=50.0)
    b.set(v=18.0, s=50.0)
    second = a.get("brake_command", "v_ref", "speed_error")
    assert second != first and second == b.get("brake_command", "v_ref", "speed_error")
    for inst in (a, b):
        inst.fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=T)
        inst.set(v=17.5, s=53.0)
    # the next event builds on the committed one: identical histories give identical outputs
    assert a.get("brake_command", "v_ref", "speed_error") == \
        b.get("brake_command", "v_ref", "speed_error")
    assert a.fmu.getInteger([a.vr["executions"]]) == [2]  # one committed, one shown
    a.free()
    b.free()


@pytest.mark.parametrize("overrides, message", [
    (["simulation.base_step=1.0", "simulation.output_interval=1.0"],
     r"sample_time = 0.2 s is not a multiple of \[simulation\] base_step = 1.0 s"),
    (["simulation.base_step=0.3", "controller.sample_time=0.6", "simulation.output_interval=0.2"],
     r"output_interval = 0.2 s is not a multiple of base_step = 0.3 s"),
])
@pytest.mark.parametrize("algorithm", ["fixed", "jacobi"])
def test_fixed_step_timing_is_checked(built_fmus, overrides, message, algorithm):
    with pytest.raises(ScenarioError, match=message):
        run_scenario("seed000_stop_pid", overrides, algorithm=algorithm, build=False,
                     plot=False)
