"""``cosim validate`` on FMUs that crash, hang or output NaN (hostile.c, built by the tests):
each is reported in the check it happened in, naming the FMI call and how it ended; a crash or
hang in instantiation, or a second one in the same FMI function, ends the checks (the rest are
skipped, not rerun into the same fault); hangs are decided on the FMU's own CPU time and the
machine's measured speed, so a healthy FMU passes on a loaded core."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from cosim.interop.compliance import DYNAMIC_CHECKS, ERROR, SKIPPED, Options, check_fmu

# tiny C FMUs: their healthy calls take microseconds, so short limits keep the hangs cheap
QUICK = Options(strict=False, call_timeout=0.2, setup_call_timeout=0.2)

CALL = "fmi2DoStep(currentCommunicationPoint=0.0, communicationStepSize=0.125)"
# FMU -> (message of the first dynamic finding, in calling-sequence; the FMI function the
# remaining checks are skipped for)
EXPECTED = {
    "SpinInInstantiate": ("hang: fmi2Instantiate(instanceName='sequence') did not return: it "
                          "used ", "fmi2Instantiate"),
    "BlockInInstantiate": ("hang: fmi2Instantiate(instanceName='sequence') did not return and "
                           "used only ", "fmi2Instantiate"),
    "SpinInDoStep": (f"hang: {CALL} did not return: it used ", "fmi2DoStep"),
    "BlockInDoStep": (f"hang: {CALL} did not return and used only ", "fmi2DoStep"),
    "SegfaultInDoStep": (f"the host process crashed (SIGSEGV) in {CALL} during this check",
                         "fmi2DoStep"),
    "AbortInDoStep": (f"the host process crashed (SIGABRT) in {CALL} during this check",
                      "fmi2DoStep"),
    "ExitInDoStep": (f"the host process exited with status 3 in {CALL} during this check",
                     "fmi2DoStep"),
}


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_crash_or_hang_names_the_call_and_ends_the_checks(hostile_fmus, name):
    message, function = EXPECTED[name]
    problems = check_fmu(hostile_fmus[name], QUICK)
    first = [p for p in problems if p.check == "calling-sequence" and p.severity == ERROR]
    assert len(first) == 1 and first[0].message.startswith(message), problems
    if "hang" in message:  # the limit it broke and how to change it
        assert first[0].message.endswith("--call-timeout sets the limit)"), first[0].message
        kind = "over its limit of 0.2 CPU s" if "Spin" in name else "(blocked: "
        assert kind in first[0].message, first[0].message
    skipped = {p.check for p in problems if p.severity == SKIPPED}
    hit = {p.check for p in problems if p.severity == ERROR}
    assert skipped | hit | {"output-dependencies"} >= set(DYNAMIC_CHECKS), problems
    # in instantiation once, in doStep twice (output-dependencies never steps this FMU)
    assert len(hit) == (1 if function == "fmi2Instantiate" else 2), problems
    reason = f"hangs in {function}" if "hang" in message else f"crashes in {function}"
    assert all(reason in p.message for p in problems if p.severity == SKIPPED), problems


def test_nan_output_is_an_error(hostile_fmus):
    problems = check_fmu(hostile_fmus["NanOutput"], QUICK)
    errors = [p for p in problems if p.severity == ERROR]
    assert [(p.check, p.message) for p in errors] == [("calling-sequence",
                                                       "output y is nan at step 2")]


def test_timeout_bounds_the_whole_fmu(hostile_fmus):
    """--timeout is one budget for all the checks of an FMU, worker restarts included: with
    per-call limits too large to ever act, the spinning doStep ends at the budget, and the
    checks after it are skipped instead of each spending its own timeout."""
    problems = check_fmu(hostile_fmus["SpinInDoStep"],
                         Options(strict=False, call_timeout=1e6, setup_call_timeout=1e6,
                                 timeout=1.0))
    errors = [p for p in problems if p.severity == ERROR]
    assert len(errors) == 1, problems
    assert errors[0].message.startswith("hang: the checks of this FMU did not finish within "
                                        f"their budget (--timeout) while in {CALL}")
    rest = {p.check for p in problems if p.severity == SKIPPED}
    assert rest == set(DYNAMIC_CHECKS) - {errors[0].check}, problems
    assert all("ran out of their budget" in p.message for p in problems
               if p.severity == SKIPPED)


def test_a_healthy_fmu_passes_on_a_loaded_core(hostile_fmus):
    """SlowFirstStep's first fmi2DoStep needs 0.3 s of CPU, under the limit of 0.6 CPU s. The
    check runs pinned to one core beside two CPU-burning processes, so it gets at most a third
    of that core and the call takes at least three times its CPU time on the wall clock (a
    wall-clock limit of 0.6 s would call it a hang): no check may fail."""
    if not hasattr(os, "sched_setaffinity"):
        pytest.skip("needs os.sched_setaffinity (Linux)")
    cpu = min(os.sched_getaffinity(0))

    def pin() -> None:
        os.sched_setaffinity(0, {cpu})

    burners = [subprocess.Popen([sys.executable, "-c", "while True: pass"], preexec_fn=pin)
               for _ in range(2)]
    mask = os.sched_getaffinity(0)
    try:
        pin()  # this process (the workers' supervisor) and the workers it starts
        problems = check_fmu(hostile_fmus["SlowFirstStep"],
                             Options(strict=False, call_timeout=0.6, n_steps=4))
    finally:
        os.sched_setaffinity(0, mask)
        for burner in burners:
            burner.kill()
            burner.wait()
    assert not [p for p in problems if p.severity == ERROR], problems
