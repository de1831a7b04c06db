"""The FMI 3.0 checks on a third-party FMU: ``fmi3_ticker.c``, written from the standard alone
(time events announced as nextEventTime, early return, FMU state). Standard-correct, it passes
``--lenient`` (no error); with a planted fault the check of that clause fails."""

from __future__ import annotations

import shutil
import subprocess
import zipfile
from pathlib import Path

import fmpy
import pytest

from cosim.interop.compliance import ERROR, Options, check_fmu, passed
from cosim.interop.compliance.common import CONVENTION, RECOMMENDED

HERE = Path(__file__).resolve().parent

MODEL_DESCRIPTION = """<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="3.0" modelName="Ticker" instantiationToken="{ticker-1}">
  <CoSimulation modelIdentifier="Ticker" canHandleVariableCommunicationStepSize="true"
    hasEventMode="true" mightReturnEarlyFromDoStep="true" canGetAndSetFMUState="true"/>
  <DefaultExperiment startTime="0" stopTime="2" stepSize="0.1"/>
  <ModelVariables>
    <Float64 name="time" valueReference="0" causality="independent" variability="continuous"/>
    <Int32 name="ticks" valueReference="1" causality="output" variability="discrete"/>
    <Float64 name="u" valueReference="2" causality="input" start="0"/>
    <Float64 name="y" valueReference="3" causality="output"/>
  </ModelVariables>
  <ModelStructure>
    <Output valueReference="1"/>
    <Output valueReference="3" dependencies="2"/>
    <InitialUnknown valueReference="1"/>
    <InitialUnknown valueReference="3"/>
  </ModelStructure>
</fmiModelDescription>
"""


def build_ticker(dest: Path, *defines: str) -> Path:
    gcc = shutil.which("gcc")
    if gcc is None:
        pytest.skip("gcc is needed to build the third-party FMI 3 FMU")
    binary = dest.with_suffix(".so")
    subprocess.run([gcc, "-shared", "-fPIC", "-O1", f"-I{Path(fmpy.__file__).parent / 'c-code'}",
                    *(f"-D{d}" for d in defines), "-o", str(binary),
                    str(HERE / "fmi3_ticker.c"), str(HERE / "fmi3_ticker_stubs.c"), "-lm"],
                   check=True, capture_output=True)
    with zipfile.ZipFile(dest, "w") as z:
        z.writestr("modelDescription.xml", MODEL_DESCRIPTION)
        z.write(binary, "binaries/x86_64-linux/Ticker.so")
    return dest


@pytest.fixture(scope="module")
def ticker(tmp_path_factory) -> Path:
    return build_ticker(tmp_path_factory.mktemp("ticker") / "Ticker.fmu")


def test_standard_correct_fmi3_fmu_passes_lenient(ticker):
    problems = check_fmu(ticker, Options(strict=False))
    assert passed(problems), [str(p) for p in problems]
    assert not [p for p in problems if p.severity == "skipped"]
    # strict: only our conventions and the standard's recommendations fail, nothing required
    strict = check_fmu(ticker, Options(strict=True))
    assert {p.requirement for p in strict if p.severity == ERROR} <= {CONVENTION, RECOMMENDED}
    assert any(p.check == "fmi3-variables" and "without a unit" in p.message for p in strict)


def test_fmpy_runs_the_ticker_with_its_time_events(ticker):
    """The third-party FMU itself is right: fmpy with early return stops at every tick
    (k * 0.3 s) between its output points (0.25 s apart), and at t = 1 s four ticks (0, 0.3,
    0.6, 0.9 s) have been counted; between ticks the count is 1 + floor(t / 0.3)."""
    result = fmpy.simulate_fmu(str(ticker), use_event_mode=True, early_return_allowed=True,
                               stop_time=1.0, output_interval=0.25, output=["ticks"])
    times = [round(float(t), 12) for t in result["time"]]
    assert {0.3, 0.6, 0.9} <= set(times)
    assert result["ticks"][-1] == 4
    for t, ticks in zip(times, result["ticks"]):
        if abs(t / 0.3 - round(t / 0.3)) > 1e-9:  # off a tick (fmpy samples before Event Mode)
            assert ticks == 1 + int(t / 0.3)


@pytest.mark.parametrize(("fault", "check", "words"), [
    ("FAULT_PAST_EVENT", "fmi3-event-mode", "before the current time"),
    ("FAULT_STATE", "fmi3-fmu-state", "fmi3SetFMUState"),
])
def test_planted_fault_fails_its_check_even_lenient(fault, check, words, tmp_path):
    fmu = build_ticker(tmp_path / "Ticker.fmu", fault)
    problems = check_fmu(fmu, Options(strict=False))
    found = [p for p in problems if p.check == check and p.severity == ERROR]
    assert found and words in found[0].message, [str(p) for p in problems]
    assert not passed(problems)
