"""Run-dependent timings (QP solve times) are neither outputs nor FMU state: the FMU logs them
at fmi2Terminate (cosim.fmu.diagnostics) and summary.json reads them from there (issue 12)."""

from __future__ import annotations

import fnmatch
import zipfile

import pytest
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave

from cosim.fmu import diagnostics
from cosim.interop.compliance import Options
from cosim.run.master import logging_callbacks


def test_no_fmu_publishes_a_wall_clock_output(built_fmus):
    """Every output of every catalog FMU is deterministic: none matches the patterns the
    compliance suite would have to leave out of its reproducibility comparisons."""
    patterns = [p for p in Options.irreproducible if not p.startswith("description:")]
    for spec in built_fmus.values():
        md = read_model_description(str(spec.path))
        for v in md.modelVariables:
            if v.causality != "output":
                continue
            assert not any(fnmatch.fnmatch(v.name, p) for p in patterns), (spec.identifier,
                                                                           v.name)
            assert "wall-clock" not in (v.description or ""), (spec.identifier, v.name)


class _Rsmpc:
    """StopRsmpc in fmpy, as any FMI host runs it, with its log collected."""

    def __init__(self, path, name: str) -> None:
        md = read_model_description(str(path))
        self.vr = {v.name: v.valueReference for v in md.modelVariables}
        self.log: list[str] = []
        self.callbacks = logging_callbacks(lambda status, text: self.log.append(text))
        self.fmu = FMU2Slave(guid=md.guid, unzipDirectory=extract(str(path)),
                             modelIdentifier=md.coSimulation.modelIdentifier, instanceName=name)
        self.fmu.instantiate(callbacks=self.callbacks, loggingOn=True)
        self.fmu.setupExperiment(startTime=0.0)
        self.fmu.enterInitializationMode()
        self.fmu.exitInitializationMode()

    def run(self, steps: int) -> None:
        v, s = 20.0, 0.0
        for k in range(steps):
            self.fmu.setReal([self.vr["v"], self.vr["s"], self.vr["a_c"]], [v, s, -0.3])
            self.fmu.doStep(currentCommunicationPoint=0.2 * k, communicationStepSize=0.2)
            s += 0.2 * v
            v = max(v - 0.1, 0.0)


def test_solve_times_reach_the_host_through_the_log_only(built_fmus):
    """Two instances given the same inputs have byte-identical serialized FMU states (no
    measured time in them); at fmi2Terminate each logs its solve times, one line."""
    a, b = (_Rsmpc(built_fmus["StopRsmpc"].path, f"rsmpc{k}") for k in (1, 2))
    try:
        for inst in (a, b):
            inst.run(40)
        states = [i.fmu.serializeFMUstate(i.fmu.getFMUstate()) for i in (a, b)]
        assert bytes(states[0]) == bytes(states[1])
        assert b"solve_time" not in bytes(states[0])
        executions = a.fmu.getInteger([a.vr["executions"]])[0]
        assert 1 < executions < 40  # self-triggered: fewer events than samples
        for inst in (a, b):
            inst.fmu.terminate()
            lines = [m for m in inst.log if diagnostics.TAG in m]
            assert len(lines) == 1 and lines[0].startswith(f"{inst.fmu.instanceName}: ")
            figures = diagnostics.parse(inst.log)
            assert figures["qp_solve_events"] == executions
            assert 0.0 < figures["qp_solve_time_median"] <= figures["qp_solve_time_total"]
    finally:
        for inst in (a, b):
            inst.fmu.freeInstance()


def test_summary_reads_the_logged_figures(built_fmus):
    """seed 000 RSMPC through the master: the summary's solve times are the logged ones."""
    from cosim.run.simulate import run_scenario

    r = run_scenario("seed000_stop_rsmpc", ["simulation.stop_time=10"], build=False,
                     plot=False)
    logged = r.diagnostics["controller"]
    assert logged["qp_solve_events"] == r.executions["controller"]
    assert r.summary["qp_solve_time_median_s"] == logged["qp_solve_time_median"] > 0.0
    assert r.summary["qp_solve_time_total_s"] == logged["qp_solve_time_total"]
    assert "qp_solve_time_median" not in r.final_outputs["controller"]
    assert "plant" not in r.diagnostics  # a plant has nothing to report


def test_parse_takes_the_last_well_formed_line():
    good = diagnostics.message("c", {"qp_solve_time_total": 0.5, "bad": float("nan"),
                                     "text": "x"})
    assert good == 'c: diagnostics {"qp_solve_time_total": 0.5}'
    assert diagnostics.parse(["c: diagnostics {not json", good, "c: done"]) == \
        {"qp_solve_time_total": 0.5}
    assert diagnostics.parse(["c: diagnostics [1]", "no tag here"]) == {}


def test_window_bounds_the_memory():
    times = diagnostics.SolveTimes(window=3)
    for x in (0.0, 1.0, 2.0, 3.0, 4.0):
        times.add(x, cpu_s=0.5)
    assert list(times.recent) == [2.0, 3.0, 4.0]
    assert list(times.recent_cpu) == [0.5, 0.5, 0.5]
    assert times.diagnostics() == pytest.approx({
        "qp_solve_time_median": 3.0, "qp_solve_time_total": 10.0, "qp_solve_events": 5,
        "qp_cpu_time_total": 2.5, "qp_cpu_time_median": 0.5})


def test_bundled_with_every_fmu(built_fmus):
    """The module travels in the bundle (the slave base imports it)."""
    for spec in built_fmus.values():
        with zipfile.ZipFile(spec.path) as z:
            assert any(n.endswith("cosim/fmu/diagnostics.py") for n in z.namelist()), \
                spec.identifier
