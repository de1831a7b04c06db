"""setFMUstate restores only the state when the parameters are unchanged (it rebuilt the whole
core: DARE, reachable sets, route, QP set-up, 8 ms against 0.25 ms per doStep for RSMPC), and
still rebuilds it when they differ; the run after a restore is the same either way."""

from __future__ import annotations

from controllers.mpc.stop_rsmpc_fmu import StopRsmpcFmu


def _slave() -> StopRsmpcFmu:
    slave = StopRsmpcFmu(instance_name="rsmpc")
    slave.setup_experiment(0.0)
    slave.enter_initialization_mode()
    slave.exit_initialization_mode()
    return slave


def _run(slave: StopRsmpcFmu, k0: int, k1: int) -> list[float]:
    out = []
    vr = {v.name: i for i, v in enumerate(slave.variables)}
    for k in range(k0, k1):
        slave.set_real([vr["v"], vr["s"], vr["a_c"]], [20.0 - 0.4 * k * 0.2, 4.0 * k, -0.4])
        slave.do_step(0.2 * k, 0.2)
        out.append(slave.get_real([vr["brake_command"]])[0])
    return out


def test_restore_keeps_the_core_when_parameters_are_unchanged():
    slave = _slave()
    _run(slave, 0, 5)
    state = slave._get_fmu_state()
    first = _run(slave, 5, 15)
    core = slave.core
    slave._set_fmu_state(state)
    assert slave.core is core  # not rebuilt
    assert _run(slave, 5, 15) == first


def test_restore_into_an_instance_with_other_parameters_rebuilds_the_core():
    slave = _slave()
    _run(slave, 0, 5)
    state = slave._get_fmu_state()
    first = _run(slave, 5, 15)
    other = StopRsmpcFmu(instance_name="other")
    other.values["N"] = 4  # another horizon: its core is another problem
    other.setup_experiment(0.0)
    other.enter_initialization_mode()
    other.exit_initialization_mode()
    core = other.core
    other._set_fmu_state(state)
    assert other.core is not core and other.values["N"] == slave.values["N"]
    assert _run(other, 5, 15) == first
