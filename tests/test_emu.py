"""EMU coupler-chain plant: conservation, damping, rigid limit, envelope, step sizes, FMUs."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from fmi_state_helpers import FmuInstance, rerun_after_restore
from scipy.integrate import solve_ivp

from cosim.fmu.state import to_ticks
from plants.emu import Emu, EmuParams, emu_config
from plants.route import GRAVITY, Route, StepProfile


def run(emu: Emu, forces, duration: float, step: float, t0: float = 0.0) -> None:
    """Advance ``emu`` with constant per-unit forces over communication steps of ``step`` s."""
    t, end = to_ticks(t0), to_ticks(t0 + duration)
    inputs = {f"force[{i + 1}]": float(f) for i, f in enumerate(forces)}
    h = to_ticks(step)
    while t < end:
        dt = min(h, end - t)
        emu.advance(t, dt, inputs)
        t += dt


UNIT_ROUNDOFF = np.finfo(float).eps / 2


def substep_rounding_bound(emu: Emu, forces) -> np.ndarray:
    """Bound on the rounding error one exact-exponential sub-step adds to each of (x, v).

    A sub-step is ``state' = Phi state + Gamma f`` with Phi, Gamma from ``expm``, whose backward
    error is at most u ||A h||_1 (Al-Mohy & Higham 2009), plus the 2n-term products and their
    sums (at most 4n + 2 roundings): kappa u (|Phi| |state| + |Gamma| |f|) to first order in u.
    """
    h_ticks = to_ticks(emu.p.max_step)
    prop = emu._propagator(h_ticks)
    kappa = np.linalg.norm(emu._A * emu.p.max_step, 1) + 4 * emu.n + 2
    state = np.abs(np.concatenate((emu.x, emu.v)))
    return kappa * UNIT_ROUNDOFF * (np.abs(prop.phi) @ state
                                   + np.abs(prop.gamma) @ np.abs(np.asarray(forces, float)))


def run_with_bound(emu: Emu, forces, duration: float, step: float) -> np.ndarray:
    """:func:`run` from the plant's time; returns the summed per-sub-step rounding bound on (x, v)
    (the larger of the bounds at the start and the end, times the number of sub-steps)."""
    before = substep_rounding_bound(emu, forces)
    run(emu, forces, duration, step, t0=emu.t_ticks / 1e9)
    substeps = round(duration / emu.p.max_step)
    return substeps * np.maximum(before, substep_rounding_bound(emu, forces))


def frictionless(n: int = 3, **kw) -> EmuParams:
    p = emu_config("crh380a_3unit") if n == 3 else emu_config("crh3_8car")
    zero = (0.0,) * n
    return replace(p, davis_a=zero, davis_b=zero, davis_c=zero,
                   max_traction_force=(1e9,) * n, max_traction_power=(1e12,) * n,
                   max_brake_force=(1e9,) * n, max_brake_power=(1e12,) * n, **kw)


def test_coupler_chain_conserves_momentum_and_damps_relative_motion() -> None:
    """No resistance, internal forces only: momentum constant (to the summed rounding bound of
    the sub-steps, not a fixed tolerance), relative speeds decay."""
    p = frictionless()
    emu = Emu(p, Route.flat(), v0=20.0)
    emu.v = np.array([21.0, 19.0, 20.5])
    emu.held = False
    m = np.array(p.masses)
    momentum_weights = np.concatenate((np.zeros(emu.n), m))
    momentum0 = float(m @ emu.v)
    spread0 = np.ptp(emu.v)
    energies = []
    bound = 0.0
    for _ in range(50):
        bound += momentum_weights @ run_with_bound(emu, [0.0, 0.0, 0.0], 0.1, 0.1)
        assert abs(float(m @ emu.v) - momentum0) <= bound
        # kinetic energy relative to the centre of mass plus spring energy never grows
        vc = momentum0 / m.sum()
        stretch = emu.x[:-1] - emu.x[1:]
        energies.append(0.5 * float(m @ (emu.v - vc) ** 2)
                        + 0.5 * p.coupler_stiffness * float(stretch @ stretch))
    assert all(b <= a + 1e-9 for a, b in zip(energies, energies[1:], strict=False))
    assert np.ptp(emu.v) < 1e-6 * spread0
    # forces equal and opposite on the end units leave the momentum unchanged too
    bound += momentum_weights @ run_with_bound(emu, [5e4, 0.0, -5e4], 5.0, 0.2)
    assert abs(float(m @ emu.v) - momentum0) <= bound
    assert bound < 1e-9 * momentum0  # the bound itself is a tight one
    assert emu.coupler_forces()[0] == pytest.approx(5e4, rel=1e-3)  # front pulled: tension


def test_stiff_couplers_match_single_mass_model() -> None:
    """Very stiff couplers: the chain moves as one mass M dv/dt = F - sum(F_N)(v)."""
    p = emu_config("crh380a_3unit", coupler_stiffness=1e10, coupler_damping=1e9,
                   max_step=0.05)
    p = replace(p, max_traction_force=(1e9,) * 3, max_traction_power=(1e12,) * 3)
    emu = Emu(p, Route.flat(), v0=10.0)
    force = 2e5  # N on the leading unit only
    run(emu, [force, 0.0, 0.0], 120.0, 0.2)
    mass = sum(p.masses)
    a, b, c = sum(p.davis_a), sum(p.davis_b), sum(p.davis_c)

    def rhs(_t, y):
        return [(force - (a + b * y[0] + c * y[0] ** 2)) / mass, y[0]]

    sol = solve_ivp(rhs, (0.0, 120.0), [10.0, 0.0], rtol=1e-11, atol=1e-9)
    v_ref, s_ref = sol.y[0, -1], sol.y[1, -1]
    assert np.allclose(emu.v, v_ref, atol=1e-4)
    assert emu.outputs()["s"] == pytest.approx(s_ref, abs=5e-3)


def test_constant_force_without_resistance_is_analytic() -> None:
    """Same acceleration on every unit: v = a t and s = a t^2 / 2 to the rounding bound (a
    speed error made at t_k grows the position error over the remaining T - t_k)."""
    p = frictionless()
    emu = Emu(p, Route.flat(), v0=0.0)
    forces = np.array(p.masses) * 0.3  # same acceleration on every unit: couplers stay slack
    duration, step = 30.0, 0.2
    bound_v = bound_s = 0.0
    for k in range(round(duration / step)):
        b = run_with_bound(emu, forces, step, step)
        bound_v += b[emu.n:].max()
        bound_s += b[:emu.n].max() + (duration - k * step) * b[emu.n:].max()
    assert bound_v < 1e-9 * 9.0 and bound_s < 1e-9 * 135.0  # a tight bound
    assert np.all(np.abs(emu.v - 0.3 * duration) <= bound_v)
    assert abs(emu.outputs()["s"] - 0.5 * 0.3 * duration**2) <= bound_s
    assert np.allclose(emu.coupler_forces(), 0.0, atol=1e-3)


def _run_steps(p: EmuParams, route: Route, steps: list[float]) -> dict[str, float]:
    emu = Emu(p, route, v0=15.0)
    t, k, end = 0, 0, to_ticks(60.0)
    forces = {f"force[{i}]": 1.2e5 for i in (1, 2, 3)}
    while t < end:
        h = min(to_ticks(steps[k % len(steps)]), end - t)
        emu.advance(t, h, forces)
        t += h
        k += 1
    return emu.outputs()


def test_results_do_not_depend_on_the_communication_step() -> None:
    """Steps on the max_step grid: same trajectory to rounding; off the grid (split sub-steps):
    same to the integrator's accuracy. Noise included (drawn per absolute interval). Force
    outputs are compared to the integrator's accuracy relative to the applied forces (1.2e5 N):
    a coupler force is a small difference of them (5.3 kN with the equal traction split)."""
    p = emu_config("crh380a_3unit", disturbance_accel_std=0.05, disturbance_interval=0.2,
                   disturbance_seed=3)
    route = Route("g", 1e6, StepProfile.from_pairs([[0.0, 0.0], [300.0, 12.0]]))
    base = _run_steps(p, route, [0.2])
    for steps, rel, abs_ in (([0.05], 1e-9, 1e-6), ([1.0, 0.15, 0.5], 1e-9, 1e-6),
                             ([0.07], 1e-4, 1e-2), ([1.0, 0.013, 0.5], 1e-4, 1e-2)):
        other = _run_steps(p, route, steps)
        for key, value in base.items():
            tol = max(abs_, rel * 1.2e5) if "force" in key else abs_
            assert other[key] == pytest.approx(value, rel=rel, abs=tol), (steps, key)


def test_traction_and_brake_envelope() -> None:
    p = emu_config("crh380a_3unit")
    emu = Emu(p, Route.flat(), v0=50.0)
    tl, bl = emu.traction_limit(), emu.brake_limit()
    for i in range(3):
        assert tl[i] == pytest.approx(min(p.max_traction_force[i], p.max_traction_power[i] / 50))
        assert bl[i] == pytest.approx(min(p.max_brake_force[i], p.max_brake_power[i] / 50))
    run(emu, [1e7, 1e7, -1e7], 0.2, 0.2)
    applied = [emu.outputs()[f"applied_force[{i}]"] for i in (1, 2, 3)]
    v = emu.v
    assert applied[0] == pytest.approx(min(p.max_traction_force[0], p.max_traction_power[0]
                                           / v[0]), rel=1e-3)
    assert applied[2] == pytest.approx(-min(p.max_brake_force[2], p.max_brake_power[2] / v[2]),
                                       rel=1e-3)


def test_trailers_of_crh3_have_no_traction() -> None:
    p = emu_config("crh3_8car")
    assert [f > 0 for f in p.max_traction_force] == [True, False, True, False, False, True,
                                                     False, True]
    p3 = emu_config("crh3_3car")
    assert p3.masses[1] - p.masses[1] == pytest.approx(5e3)  # +5 t passengers on car 2
    assert p3.max_traction_force[1] == 0.0


def test_neutral_section_cuts_traction() -> None:
    route = Route("n", 1e5, StepProfile.from_pairs(None, 0.0),
                  neutral=StepProfile.from_intervals([[1000.0, 1200.0]], 0.0, value=1.0))
    p = emu_config("crh380a_3unit")
    emu = Emu(p, route, v0=0.0, s0=1000.0 + 38.0 + 1.0)  # unit 1 midpoint just inside
    out = emu.outputs()
    assert out["traction_limit[1]"] == 0.0 and out["traction_limit[2]"] > 0.0
    run(emu, [1e5, 0.0, 0.0], 0.2, 0.2)
    assert emu.applied[0] == 0.0


def test_grade_resistance_by_length_share() -> None:
    """Unit 1 (76 m) with 30 m on a 10 permille grade feels 30/76 of it."""
    route = Route("g", 1e6, StepProfile.from_pairs([[0.0, 0.0], [1000.0, 10.0]]))
    p = emu_config("crh380a_3unit")
    emu = Emu(p, route, v0=0.0, s0=1030.0)
    force = emu._route_force(emu.x)
    assert force[0] == pytest.approx(p.masses[0] * GRAVITY * 10.0 / 1000 * 30 / 76)
    assert force[1] == 0.0 and force[2] == 0.0


def test_standstill_is_held_by_the_brake_and_rolls_back_without() -> None:
    route = Route("up", 1e6, StepProfile.from_pairs([[-1e5, 10.0]]))
    p = emu_config("crh380a_3unit")
    emu = Emu(p, route, v0=0.0, s0=5000.0)
    run(emu, [-1e5, -1e5, -1e5], 10.0, 0.2)
    assert emu.held and np.all(emu.v == 0.0) and emu.outputs()["s"] == 5000.0
    run(emu, [0.0, 0.0, 0.0], 10.0, 0.2, t0=10.0)
    assert not emu.held and emu.outputs()["v"] < -0.1  # rolls back down the grade
    # and comes to rest again when braked
    run(emu, [-1.5e5, -1.5e5, -1.5e5], 20.0, 0.2, t0=20.0)
    assert emu.held and emu.outputs()["v"] == 0.0


def test_state_round_trip() -> None:
    p = emu_config("crh380a_3unit", disturbance_accel_std=0.1)
    emu = Emu(p, Route.flat(), v0=30.0)
    run(emu, [5e4, 0.0, 5e4], 5.0, 0.2)
    state = emu.get_state()
    run(emu, [5e4, 0.0, -5e4], 5.0, 0.2, t0=5.0)
    first = emu.outputs()
    emu.set_state(state)
    run(emu, [5e4, 0.0, -5e4], 5.0, 0.2, t0=5.0)
    assert emu.outputs() == first


def test_energy_counts_traction_and_regeneration() -> None:
    p = frictionless()
    p = replace(p, max_traction_force=(1e5,) * 3)
    emu = Emu(p, Route.flat(), v0=20.0)
    run(emu, [1e5, 1e5, 1e5], 10.0, 0.2)
    ke = 0.5 * sum(p.masses) * (float(np.mean(emu.v)) ** 2 - 20.0**2)
    assert emu.traction_energy == pytest.approx(ke, rel=1e-6)
    e0 = emu.regenerated_energy
    run(emu, [-5e4, -5e4, -5e4], 5.0, 0.2, t0=10.0)
    assert emu.regenerated_energy - e0 > 0.0


@pytest.mark.parametrize("name, value", [("masses", (1.0, -1.0, 1.0)), ("max_step", 0.0),
                                         ("coupler_damping", -1.0)])
def test_bad_parameters_are_rejected(name: str, value) -> None:
    with pytest.raises(ValueError, match=name):
        Emu(replace(emu_config("crh380a_3unit"), **{name: value}), Route.flat())
    with pytest.raises(ValueError, match="unknown"):
        emu_config("crh999")


def test_emu_fmus_close_the_loop_through_the_master(built_fmus) -> None:
    """Emu3 + EmuSpeedPid3 FMUs (seed 004 scenario, first 260 s): CTCS-3 tracking."""
    from cosim.run.simulate import run_scenario

    result = run_scenario("seed004_crh3_pid",
                          overrides={"simulation.stop_time": 260.0}, plot=False)
    s = result.summary
    assert s["ctcs3_speed_error_ok"] is True
    assert s["max_abs_speed_error_kmh"] < 0.5
    frame = result.frame
    # traction only on the motor cars 1 and 3 (car 2 is a trailer)
    assert frame["plant.applied_force[2]"].max() <= 0.0
    assert math.isclose(frame["plant.v"].iloc[-1], 45.0, abs_tol=0.05)


def test_emu_fmus_serialized_state_reproduces_the_rest_of_the_run(built_fmus) -> None:
    """Emu3 (with noise) + EmuSpeedPid3: serialize both states mid-run, finish, restore, rerun."""
    def Inst(ident: str, strings: dict, reals: dict) -> FmuInstance:  # noqa: N802
        return FmuInstance(str(built_fmus[ident].path), ident, strings, reals=reals)

    plant = Inst("Emu3", {"configuration": "crh3_3car", "route": "seed004_level"},
                 {"disturbance_accel_std": 0.05})
    ctl = Inst("EmuSpeedPid3", {"reference": "seed004_crh3_reference"},
               {"mass": 171e3, "sample_time": 1.0})
    meas = ["v", "s"] + [f"traction_limit[{i}]" for i in (1, 2, 3)] + \
        [f"brake_limit[{i}]" for i in (1, 2, 3)]
    forces = [f"force[{i}]" for i in (1, 2, 3)]

    def step(k: int) -> list[float]:
        ctl.set(meas, plant.get(meas))
        u = ctl.get(forces)
        plant.set(forces, u)
        plant.fmu.doStep(currentCommunicationPoint=float(k), communicationStepSize=1.0)
        ctl.fmu.doStep(currentCommunicationPoint=float(k), communicationStepSize=1.0)
        return plant.get(["v", "s", "coupler_force[1]"]) + u

    first, second = rerun_after_restore([plant, ctl], step, 100, 260)
    assert first == second
    assert first[-1][0] == pytest.approx(45.0, abs=0.3)  # tracking the 45 m/s target
    for inst in (plant, ctl):
        inst.fmu.terminate()
        inst.fmu.freeInstance()
