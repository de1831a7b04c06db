"""Ensemble members on reset FMU instances (:mod:`cosim.run.master.pool`): a member run on the
instances a previous member of other parameters and seed left behind (fmi2Reset, fmi3Reset)
equals the same member run on fresh instances, bit for bit, in every recorded signal, every
value the master passed on, every final output and every metric, on the Python and the native
builds, the FMI 3 co-simulation builds in Event Mode and a Scheduled Execution controller; a
failed run keeps none of its instances."""

from __future__ import annotations

import ctypes
from typing import Any

import pandas as pd
import pytest

from cosim.build.python import ROOT, build_clocked, build_stale, catalog
from cosim.fmu.state import to_ticks
from cosim.run import isolation
from cosim.run.master import native_loop
from cosim.run.master.errors import SimulationError
from cosim.run.master.fmi2 import Fmi2Unit
from cosim.run.master.fmi3 import Fmi3Unit
from cosim.run.master.pool import InstancePool
from cosim.run.master.unit import Unit
from cosim.run.scenario import load_scenario
from cosim.run.simulate import ensure_built, run_scenario

SCENARIO = "seed000_stop_rmpc"
NATIVE = {"plant.build": "native", "controller.build": "native"}
# two members: other disturbance seed, other horizon (a parameter the controller's set-up reads)
FIRST = {"plant.disturbance_amplitude": 0.02, "plant.disturbance_seed": 3, "controller.N": 5}
SECOND = {"plant.disturbance_amplitude": 0.02, "plant.disturbance_seed": 8, "controller.N": 10}
# measurements of the run, not results of it: wall and solver times
MEASURED_PREFIXES = ("wall_time_s", "real_time_factor", "fmu_wall_time_s", "qp_solve_time_",
                     "qp_cpu_time_")


def _results(result: Any) -> dict[str, Any]:
    """What a member produces, the measured times left out."""
    return {"summary": {k: v for k, v in result.summary.items()
                        if not k.startswith(MEASURED_PREFIXES)},
            "final_outputs": result.final_outputs, "values": result.connection_values,
            "changes": result.connection_changes, "executions": result.executions,
            "do_steps": result.do_steps, "sim_time_s": result.sim_time_s,
            "terminated_by": result.terminated_by}


def _member(overrides: dict[str, Any], pool: InstancePool, scenario: Any = SCENARIO) -> Any:
    return run_scenario(scenario, overrides=overrides, build=False, plot=False, pool=pool)


def _reset_equals_fresh(scenario: Any, first: dict[str, Any], second: dict[str, Any],
                        units: int, varied: str) -> list[Unit]:
    """Member ``second`` on the instances member ``first`` left in a pool equals it on fresh
    instances (and differs from ``first`` in ``varied``); the kept instances."""
    pool = InstancePool()
    one = _member(first, pool, scenario)
    kept: list[Unit] = pool.kept()
    assert len(kept) == units
    reset = _member(second, pool, scenario)
    assert {id(u) for u in pool.kept()} == {id(u) for u in kept}  # the same instances served
    fresh = _member(second, InstancePool(), scenario)
    pd.testing.assert_frame_equal(reset.frame, fresh.frame, check_exact=True)
    assert _results(reset) == _results(fresh)
    assert not one.frame[varied].equals(reset.frame[varied])  # another run
    pool.clear()
    assert len(pool) == 0
    return kept


@pytest.mark.parametrize("build", [{}, NATIVE], ids=["python", "native"])
def test_a_reset_member_equals_a_fresh_one(built_fmus, build: dict[str, str]) -> None:
    ensure_built(load_scenario(SCENARIO, build))
    _reset_equals_fresh(SCENARIO, {**FIRST, **build}, {**SECOND, **build}, 2, "plant.s")


def test_a_reset_fmi3_member_equals_a_fresh_one(built_fmus_fmi3) -> None:
    """The FMI 3.0 co-simulation builds under the event algorithm: fmi3Reset."""
    fmi3 = {"simulation.fmi_version": 3}
    kept = _reset_equals_fresh(SCENARIO, {**FIRST, **fmi3}, {**SECOND, **fmi3}, 2, "plant.s")
    assert all(isinstance(u, Fmi3Unit) for u in kept)


@pytest.mark.slow
def test_a_reset_scheduled_execution_member_equals_a_fresh_one() -> None:
    """scenarios/mixed/seed000_stop_pid_scheduled.toml: a Scheduled Execution controller
    activated by its periodic clock, an FMI 3 co-simulation train and an FMI 2 controller in
    one run; every unit reset (fmi3Reset, fmi2Reset) between members of other start speeds
    and reference decelerations."""
    from cosim.run.master.scheduled import Fmi3ScheduledUnit

    specs = catalog()
    build_stale([specs["BrakeDelayTrain"], specs["StopPid"]], fmi_version=3)
    build_stale([specs["BrakeDelayTrain"], specs["StopPid"]])
    build_clocked(specs["StopPid"], "periodic", "se")
    path = ROOT / "scenarios" / "mixed" / "seed000_stop_pid_scheduled.toml"
    first = {"plant.v0": 19.0, "controller.ref_decel": 0.45, "shadow.ref_decel": 0.45}
    second = {"plant.v0": 20.5, "controller.ref_decel": 0.55, "shadow.ref_decel": 0.55}
    kept = _reset_equals_fresh(path, first, second, 3, "plant.s")
    assert sum(isinstance(u, Fmi3ScheduledUnit) for u in kept) == 1


def test_a_reused_instance_is_traced_once_however_many_members(built_fmus, monkeypatch
                                                                ) -> None:
    """In a worker (a child process of :mod:`cosim.run.isolation`), each run traces its
    units' FMU calls: a unit the pool kept is traced again from its own methods, so every
    traced call wraps the method once after any number of members (a wrapper per member
    grew the call depth by one per member, until a worker's thousandth member failed with
    RecursionError)."""
    # the breadcrumb and labels a child has (shared memory)
    monkeypatch.setattr(isolation, "_crumb", (ctypes.c_double * 3)())
    monkeypatch.setattr(isolation, "_labels", (ctypes.c_char * isolation._LABEL_BYTES)())
    pool = InstancePool()
    quick = {"simulation.stop_time": 2.0}
    for seed in range(3):
        assert _member({**quick, "plant.disturbance_seed": seed + 1,
                        "plant.disturbance_amplitude": 0.02}, pool).completed
    for unit in pool.kept():
        for method, _ in isolation.CALLS:
            traced = getattr(unit, method)
            assert not hasattr(traced.__wrapped__, "__wrapped__"), (unit.name, method)
    pool.clear()


def test_a_failed_run_keeps_none_of_its_instances(built_fmus, monkeypatch) -> None:
    pool = InstancePool()
    quick = {"simulation.stop_time": 2.0}
    _member(quick, pool)
    assert len(pool) == 2
    real_step = Fmi2Unit.step_to

    def failing_step(self: Fmi2Unit, ticks: int) -> int:
        if self.name == "plant" and ticks > to_ticks(1.0):
            raise SimulationError("plant: doStep at t = 1 s failed: test fault")
        return real_step(self, ticks)

    monkeypatch.setattr(Fmi2Unit, "step_to", failing_step)
    monkeypatch.setenv(native_loop.ENV, "off")  # the fault is injected into the Python loop
    with pytest.raises(SimulationError, match="test fault"):
        _member(quick, pool)
    assert len(pool) == 0  # freed, not kept in the state the failure left
    monkeypatch.undo()
    again = _member(quick, pool)
    assert again.completed and len(pool) == 2
    pool.clear()


def test_a_run_failing_to_load_frees_the_instances_it_took(built_fmus, monkeypatch) -> None:
    """A run whose loading fails after it took its instances from the pool (here: a fault
    injected into the connections' ordering) frees them: none is kept, none is lost."""
    from cosim.run.master.core import Master
    from cosim.run.scenario import ScenarioError

    pool = InstancePool()
    quick = {"simulation.stop_time": 2.0}
    _member(quick, pool)
    kept = pool.kept()
    assert len(kept) == 2
    freed: list[Unit] = []
    real_free = Fmi2Unit.free

    def counted_free(self: Fmi2Unit) -> None:
        freed.append(self)
        real_free(self)

    def broken(self: Master) -> None:
        raise ScenarioError("test fault after the instances were taken")

    monkeypatch.setattr(Fmi2Unit, "free", counted_free)
    monkeypatch.setattr(Master, "_value_flow_order", broken)
    with pytest.raises(ScenarioError, match="test fault"):
        _member(quick, pool)
    assert len(pool) == 0
    assert sorted(map(id, freed)) == sorted(map(id, kept))
    monkeypatch.undo()
    again = _member(quick, pool)  # new instances
    assert again.completed and len(pool) == 2
    pool.clear()
