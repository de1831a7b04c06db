"""``cosim validate`` on FMI 3.0 Clocks (cosim.interop.compliance.clocks): the Modelica
Reference FMU Clocks (Scheduled Execution) and our C test FMUs pass with their partitions
activated at their documented or analytic times; modelDescriptions with a planted fault fail
with the FMI 3.0 clause of the rule they break; legal but unusual ones raise nothing."""

from __future__ import annotations

import re
import zipfile
from pathlib import Path

import pytest

from cosim.interop.compliance import (
    CONVENTION,
    ERROR,
    NOTE,
    RECOMMENDED,
    SKIPPED,
    Options,
    check_fmu,
    format_report,
    passed,
)
from cosim.interop.compliance.clocks import clock_checks

# a Scheduled Execution FMU: a constant clock "period" (0.1 s), a countdown "alarm" set by it,
# an output clock "done"; count and y are clocked outputs
PARTITIONS = """<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="3.0" modelName="Partitions" instantiationToken="{p-1}">
  <ScheduledExecution modelIdentifier="Partitions"/>
  <ModelVariables>
    <Float64 name="time" valueReference="0" causality="independent" variability="continuous"/>
    <Clock name="period" valueReference="1" causality="input" intervalVariability="constant"
      intervalDecimal="0.1" priority="0"/>
    <Clock name="alarm" valueReference="2" causality="input" intervalVariability="countdown"
      priority="1" clocks="1"/>
    <Clock name="done" valueReference="3" causality="output" intervalVariability="triggered"
      clocks="1 2"/>
    <Int32 name="count" valueReference="4" causality="output" clocks="1"/>
    <Float64 name="u" valueReference="5" causality="input" variability="discrete" start="0"/>
    <Float64 name="y" valueReference="6" causality="output" variability="discrete"
      clocks="1 2"/>
  </ModelVariables>
  <ModelStructure>
    <Output valueReference="3" dependencies="1 2"/>
    <Output valueReference="4" dependencies="1"/>
    <Output valueReference="6" dependencies="1 2 5"/>
  </ModelStructure>
</fmiModelDescription>
"""

# (planted fault: text replaced -> replacement, the FMI 3.0 section cited, words of the message)
FAULTS = {
    "clock reference to no variable": (
        'priority="1" clocks="1"', 'priority="1" clocks="9"', "2.4.7.4",
        "lists '9', which is no variable"),
    "clock reference to a non-clock": (
        'clocks="1 2"/>\n    <Int32', 'clocks="1 5"/>\n    <Int32', "2.4.7.4",
        "lists '5', which is Float64 u, not a Clock"),
    "constant clock without interval": (
        'intervalDecimal="0.1" ', "", "2.2.8.2", "a constant clock declares its interval"),
    "constant clock with only a counter": (
        'intervalDecimal="0.1" ', 'supportsFraction="true" intervalCounter="1" resolution="10" ',
        "2.4.4", "declares intervalCounter but no intervalDecimal"),
    "clock with causality parameter": (
        'name="period" valueReference="1" causality="input"',
        'name="period" valueReference="1" causality="parameter"', "2.4.7.4",
        "causality 'parameter'"),
    "clock with variability fixed": (
        'name="alarm" valueReference="2"', 'name="alarm" variability="fixed" valueReference="2"',
        "2.4.7.4", "a Clock is discrete"),
    "output clock not triggered": (
        'causality="output" intervalVariability="triggered"',
        'causality="output" intervalVariability="countdown"', "2.2.8.2",
        "output Clocks are triggered"),
    "output clock with a priority": (
        'intervalVariability="triggered"\n', 'intervalVariability="triggered" priority="2"\n',
        "2.4.4", "output Clock done declares a priority"),
    "input clock of Scheduled Execution without priority": (
        ' priority="1" clocks="1"', ' clocks="1"', "2.4.4", "input Clock alarm has no priority"),
    "interval of a countdown clock": (
        'intervalVariability="countdown"\n      priority="1"',
        'intervalVariability="countdown" intervalDecimal="0.2"\n      priority="1"', "2.4.4",
        "intervalDecimal = '0.2', which is used by periodic"),
    "shift without interval": (
        'intervalVariability="countdown"\n      priority="1"',
        'intervalVariability="countdown" shiftDecimal="0.2"\n      priority="1"', "2.4.4",
        "shiftDecimal = '0.2', which requires intervalDecimal"),
    "counter without supportsFraction": (
        'intervalDecimal="0.1" ', 'intervalDecimal="0.1" intervalCounter="1" resolution="10" ',
        "2.4.4", "intervalCounter = '1', which is used by periodic Clocks with supportsFraction"),
    "negative interval": (
        'intervalDecimal="0.1" ', 'intervalDecimal="-0.1" ', "2.4.4", "must be > 0.0"),
    "clocked continuous variable": (
        'causality="output" variability="discrete"\n      clocks',
        'causality="output"\n      clocks',
        "2.4.7.4", "variability 'continuous'; a clocked variable is discrete or tunable"),
    "local clock in Scheduled Execution": (
        "  </ModelVariables>", '    <Clock name="debug" valueReference="7" causality="local" '
        'intervalVariability="triggered"/>\n  </ModelVariables>', "2.2.8.2",
        "local Clocks are not allowed in Scheduled Execution"),
    "clock array": (
        'clocks="1 2"/>\n    <Int32', 'clocks="1 2"><Dimension start="2"/></Clock>\n    <Int32',
        "2.4.7.2", "Clocks are scalar"),
    "previous on an unclocked variable": (
        'name="u" valueReference="5"', 'name="u" previous="6" valueReference="5"', "2.4.7.4",
        "only clocked discrete variables have previous"),
    "co-simulation with clocks and no Event Mode": (
        '<ScheduledExecution modelIdentifier="Partitions"/>',
        '<CoSimulation modelIdentifier="Partitions"/>', "4.4", "hasEventMode must be true"),
}

# legal modelDescriptions a checker might wrongly refuse
LEGAL = {
    "fixed clock without intervalDecimal (asked of the FMU)": (
        'intervalVariability="constant"\n      intervalDecimal="0.1"',
        'intervalVariability="fixed"'),
    "periodic clock in counters as well": (
        'intervalDecimal="0.1" ', 'intervalDecimal="0.1" shiftDecimal="0.05" '
        'supportsFraction="true" intervalCounter="1" shiftCounter="1" resolution="10" '),
    "clock attributes from a ClockType": (
        '<ModelVariables>', '<TypeDefinitions><ClockType name="Tick" '
        'intervalVariability="triggered"/></TypeDefinitions>\n  <ModelVariables>'),
    "tunable parameter clocked": (
        "  </ModelVariables>", '    <Float64 name="gain" valueReference="8" '
        'causality="parameter" variability="tunable" start="1" clocks="1"/>\n'
        "  </ModelVariables>"),
    "clocked state with its previous value": (
        "  </ModelVariables>", '    <Int32 name="x" valueReference="9" variability="discrete" '
        'clocks="1" previous="10"/>\n    <Int32 name="x_previous" valueReference="10" '
        'variability="discrete"/>\n  </ModelVariables>'),
    "triggered local clock in co-simulation": (
        '<ScheduledExecution modelIdentifier="Partitions"/>',
        '<CoSimulation modelIdentifier="Partitions" hasEventMode="true"/>'
        '<ModelExchange modelIdentifier="Partitions"/>'),
}


def write_fmu(dest: Path, text: str) -> Path:
    """An FMU archive holding only ``text`` as modelDescription.xml (the static checks read
    nothing else)."""
    with zipfile.ZipFile(dest, "w") as z:
        z.writestr("modelDescription.xml", text)
    return dest


def planted(tmp_path: Path, old: str, new: str) -> Path:
    assert PARTITIONS.count(old) == 1, old
    return write_fmu(tmp_path / "Planted.fmu", PARTITIONS.replace(old, new))


def test_the_base_model_description_has_no_clock_finding(tmp_path):
    assert clock_checks(write_fmu(tmp_path / "Partitions.fmu", PARTITIONS)) == []


@pytest.mark.parametrize("fault", sorted(FAULTS))
def test_planted_clock_fault_fails_citing_its_clause(tmp_path, fault):
    old, new, section, words = FAULTS[fault]
    problems = clock_checks(planted(tmp_path, old, new))
    assert problems and all(p.severity == ERROR for p in problems), problems
    cited = [p for p in problems if words in p.message]
    assert cited, [p.message for p in problems]
    assert re.search(rf"FMI 3\.0 sec\. [\d.; ]*{re.escape(section)}\b", cited[0].message), cited


def test_multiple_set_flag_on_an_output_is_a_variables_finding(tmp_path):
    path = planted(tmp_path, 'name="count" valueReference="4"',
                   'name="count" canHandleMultipleSetPerTimeInstant="false" valueReference="4"')
    (problem,) = clock_checks(path)
    assert problem.check == "fmi3-variables" and "2.4.7.4" in problem.message


@pytest.mark.parametrize("case", sorted(LEGAL))
def test_legal_clock_declarations_raise_nothing(tmp_path, case):
    old, new = LEGAL[case]
    text = PARTITIONS.replace(old, new)
    if case == "clock attributes from a ClockType":
        text = text.replace('causality="output" intervalVariability="triggered"',
                            'causality="output" declaredType="Tick"')
    if case == "triggered local clock in co-simulation":
        text = text.replace("  </ModelVariables>", '    <Clock name="debug" valueReference="7" '
                            'causality="local" intervalVariability="triggered"/>\n'
                            "  </ModelVariables>").replace(' priority="0"', "")
        text = text.replace(' priority="1"', "")
    assert text != PARTITIONS
    assert clock_checks(write_fmu(tmp_path / "Legal.fmu", text)) == []


def test_the_report_names_the_clock_check_and_its_clause(tmp_path):
    path = planted(tmp_path, *FAULTS["clock reference to no variable"][:2])
    problems = check_fmu(path, Options(dynamic=False, strict=False))
    report = format_report(path, problems)
    assert re.search(r"FAIL\s+fmi3-clocks\s+\[FMI 3\.0 2\.2\.8", report), report
    assert "sec. 2.4.7.4" in report


def note(problems: list, check: str) -> str:
    (found,) = [p.message for p in problems if p.check == check and p.severity == NOTE]
    return found


def activated(summary: str, clock: str) -> list[float]:
    """The activation times of ``clock`` in the note "<clock> at t1, t2, ... s; ..."."""
    match = re.search(rf"\b{clock} at ([^;]*?) s(;|$)", summary)
    assert match, (clock, summary)
    return [float(t) for t in match.group(1).split(", ")]


def test_reference_clocks_fmu_passes_with_its_documented_activations(reference_clocks):
    """The Reference FMU Clocks (FMI3.xml: inClock1 every 1 s, inClock3 a countdown clock set
    to tick at 4 s by inClock1's partition; stop time 10 s) passes what the standard requires;
    strict, only recommendations fail (the FMU accepts fmi3SetClock in Scheduled
    Execution)."""
    problems = check_fmu(reference_clocks, Options(strict=False))
    assert passed(problems), format_report(reference_clocks, problems)
    assert not [p for p in problems if p.severity == SKIPPED]
    summary = note(problems, "fmi3-scheduled-execution")
    assert activated(summary, "inClock1") == [float(k) for k in range(10)]
    assert activated(summary, "inClock3") == [4.0]
    strict = check_fmu(reference_clocks)
    assert {p.requirement for p in strict if p.severity == ERROR} <= {RECOMMENDED, CONVENTION}


def test_scheduled_test_fmu_partitions_run_at_their_analytic_times(c_fmus3):
    """Tasks3 (fmi3_scheduled.c): fast every 0.1 s (constant), slow every 0.25 s (fixed, asked
    of the FMU), alarm (countdown) 0.05 s after fast's 5th activation at 0.4 s."""
    problems = check_fmu(c_fmus3["Tasks3"], Options(strict=False))
    for check in ("fmi3-clocks", "fmi3-scheduled-execution"):
        assert not [p for p in problems if p.check == check and p.severity == ERROR], problems
    summary = note(problems, "fmi3-scheduled-execution")
    assert activated(summary, "fast") == pytest.approx([k / 10 for k in range(10)], abs=1e-12)
    assert activated(summary, "slow") == [0.0, 0.25, 0.5, 0.75]
    assert activated(summary, "alarm") == pytest.approx([0.45], abs=1e-12)


def test_a_changing_clock_partition_runs_where_the_fmu_says(c_fmus3):
    """TasksChanging3: slow a changing clock, first after 0.25 s, each next interval doubled
    (asked after each activation): activated at 0.25, 0.75 and 1.75 s, as the master does."""
    problems = check_fmu(c_fmus3["TasksChanging3"], Options(strict=False))
    for check in ("fmi3-clocks", "fmi3-scheduled-execution"):
        assert not [p for p in problems if p.check == check and p.severity == ERROR], problems
    summary = note(problems, "fmi3-scheduled-execution")
    assert activated(summary, "slow") == [0.25, 0.75, 1.75]


@pytest.mark.parametrize("name, ticks", [
    ("ClockedConstant3", [0.1 + 0.3 * k for k in range(7)]),  # interval 0.3 s, shift 0.1 s
    ("ClockedFixed3", [0.1 + 0.3 * k for k in range(7)]),  # the same, asked of the FMU
    ("ClockedFraction3", [0.1 + 0.3 * k for k in range(7)]),  # 3/10 s and 1/10 s
    ("ClockedTyped3", [0.1 + 0.3 * k for k in range(7)]),  # interval from its ClockType
    ("ClockedDeclared3", [0.1 + 0.3 * k for k in range(7)]),  # fixed, declared: not asked
    ("ClockedSteady3", [0.1 + 0.3 * k for k in range(7)]),  # tunable, declared: not asked
    ("ClockedChanging3", [0.3 * k for k in range(1, 7)]),  # changing, interval 0.3 s
    ("Countdown3", [0.1, 0.3, 0.7, 1.5]),  # first 0.1 s, the interval doubling at each tick
    # the same, and after each tick interval 0: a second tick in the same Event Mode
    ("CountdownTwice3", [0.1, 0.1, 0.3, 0.3, 0.7, 0.7, 1.5, 1.5]),
])
def test_clocked_cosimulation_fmus_pass_with_their_ticks(c_fmus3, name, ticks):
    problems = check_fmu(c_fmus3[name], Options(strict=False))
    assert passed(problems), format_report(c_fmus3[name], problems)
    summary = note(problems, "fmi3-clock-calls")
    assert activated(summary, "tick") == pytest.approx(ticks, abs=1e-12)


def test_a_triggered_input_clock_passes_and_is_reported_not_exercised(c_fmus3):
    """Triggered3: a co-simulation FMU whose only input clock is triggered (FMI 3.0 sec.
    2.2.8.2: it ticks when an output clock of a connected FMU does) passes, and the note says
    the clock was not exercised alone, citing the clause."""
    problems = check_fmu(c_fmus3["Triggered3"], Options(strict=False))
    assert passed(problems), format_report(c_fmus3["Triggered3"], problems)
    summary = note(problems, "fmi3-clock-calls")
    assert re.search(r"\btick not exercised \(a triggered Clock ticks when an output Clock "
                     r"of a connected FMU does, FMI 3\.0 sec\. 2\.2\.8\.2", summary), summary


def replant(src: Path, dest: Path, old: str, new: str) -> Path:
    """A copy of the FMU ``src`` whose modelDescription.xml has ``old`` replaced by ``new``."""
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dest, "w") as zout:
        for item in zin.infolist():
            data = zin.read(item)
            if item.filename == "modelDescription.xml":
                text = data.decode()
                assert text.count(old) == 1, old
                data = text.replace(old, new).encode()
            zout.writestr(item, data)
    return dest


def test_a_partition_the_binary_refuses_fails_the_scheduled_run(c_fmus3, tmp_path):
    """Tasks3 with a fifth triggered input clock in its modelDescription that its binary does
    not know: the activation returns fmi3Error, a finding citing sec. 5.2."""
    path = replant(c_fmus3["Tasks3"], tmp_path / "Tasks3.fmu", "  </ModelVariables>",
                   '    <Clock name="ghost" valueReference="9" causality="input" '
                   'intervalVariability="triggered" priority="4"/>\n  </ModelVariables>')
    problems = check_fmu(path, Options(strict=False))
    (error,) = [p for p in problems if p.check == "fmi3-scheduled-execution"
                and p.severity == ERROR]
    assert "fmi3ActivateModelPartition(ghost, 0.0) returned fmi3Error" in error.message
    assert "FMI 3.0 sec. 5.2," in error.message


def test_a_broken_clock_reference_is_cited_and_stops_the_dynamic_checks(reference_clocks,
                                                                        tmp_path):
    """fmpy cannot load a modelDescription whose clocks attribute names no variable: the
    static finding cites sec. 2.4.7.4, the loading failure is an FMI 3 calling-sequence
    finding and the other dynamic checks are skipped."""
    path = replant(reference_clocks, tmp_path / "Clocks.fmu", 'priority="2" clocks="1001"',
                   'priority="2" clocks="1009"')
    problems = check_fmu(path, Options(strict=False))
    clocks = [p.message for p in problems if p.check == "fmi3-clocks"]
    assert any("lists '1009', which is no variable (FMI 3.0 sec. 2.4.7.4" in m for m in clocks)
    assert any(p.check == "fmi3-calling-sequence" and "while loading" in p.message
               for p in problems)
    assert {p.check for p in problems if p.severity == SKIPPED} >= {
        "fmi3-scheduled-execution", "fmi3-clock-calls"}
