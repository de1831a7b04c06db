"""CRH3 single-mass plant of seed 003 (plants/crh3.py): envelope, lag, energy account (eq. 9),
step-size independence, standstill, FMU state save/restore."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from fmi_state_helpers import FmuInstance, rerun_after_restore

from cosim.fmu.state import to_ticks
from plants.crh3 import Crh3Params, Crh3Train
from plants.resistance import KMH
from plants.route import GRAVITY, Route, StepProfile, load_route


def _route() -> Route:
    """Grades both ways, a curve and a tunnel (all steps in s)."""
    curves = [[6000.0, 9000.0, 5000.0]]
    tunnels = [[12000.0, 14000.0]]
    return Route(
        "synthetic", 40000.0,
        StepProfile.from_pairs([[0.0, 0.0], [3000.0, 5.0], [8000.0, -6.0], [15000.0, 2.0],
                                [22000.0, 0.0]]),
        curve_resistance=StepProfile.from_intervals([[a, b, 600.0 / r] for a, b, r in curves]),
        tunnel_resistance=StepProfile.from_intervals([[a, b, 0.00013 * (b - a)]
                                                      for a, b in tunnels]))


def _command(t: float, p: Crh3Params) -> float:
    """Full traction, part traction, coasting, braking to a stop."""
    if t < 300.0:
        return 2.0 * p.max_traction_force
    if t < 450.0:
        return 1.5e5
    if t < 600.0:
        return 0.0
    return -0.6 * p.max_brake_force


def _run(plant: Crh3Train, t_end: float, step: float) -> float:
    """Run the command sequence; returns the top speed (m/s)."""
    k, top = 0, 0.0
    while (k + 1) * step <= t_end + 1e-9:
        plant.advance(to_ticks(k * step), to_ticks(step), {"force": _command(k * step, plant.p)})
        top = max(top, plant.v)
        k += 1
    return top


def test_envelope_is_constant_force_then_constant_power() -> None:
    p = Crh3Params()
    v_corner = p.max_traction_power / p.max_traction_force  # 31.1 m/s = 112 km/h
    # rel=1e-12 below: each side is a handful of IEEE roundings of O(1)-conditioned products and
    # quotients (<= ~10 ulp = 2e-15 relative), so 1e-12 leaves ~500x margin on any CPU
    assert p.traction_limit(0.5 * v_corner) == p.max_traction_force
    assert p.traction_limit(2.0 * v_corner) == pytest.approx(0.5 * p.max_traction_force,
                                                             rel=1e-12)
    assert p.traction_limit(381.0 * KMH) == 0.0  # Table 1: 380 km/h maximum
    assert p.brake_limit(300.0 * KMH) == pytest.approx(0.7 * p.mass, rel=1e-12)
    # Table 1 resistance at 350 km/h: 0.76 + 0.00636 * 350 + 0.000115 * 350^2 N/kN of 980 t
    w0 = 0.76 + 0.00636 * 350.0 + 0.000115 * 350.0**2
    assert p.davis.force(350.0 * KMH) == pytest.approx(w0 * p.mass * GRAVITY / 1e3, rel=1e-12)
    # the 980 t train balances near its 380 km/h maximum on level track (why P_t was chosen)
    balance = next(v for v in np.arange(300.0, 400.0, 0.5)
                   if p.davis.force(v * KMH) * v * KMH > p.max_traction_power)
    assert 370.0 <= balance <= 385.0


def test_first_order_lag_of_the_force_is_exact() -> None:
    """From rest, a demand below the envelope: F(t) = u (1 - exp(-t/tau)) for any step."""
    p = Crh3Params()
    u = 3.0e5
    for step in (0.5, 0.05):
        plant = Crh3Train(p, Route.flat())
        k = 0
        while k * step < 1.0 - 1e-9:
            plant.advance(to_ticks(k * step), to_ticks(step), {"force": u})
            k += 1
        expected = u * (1.0 - math.exp(-1.0 / p.traction_time_constant))
        # the lag is solved in closed form per step: at most 20 steps, each a few roundings and
        # one exp (<= 1 ulp) of a contraction, so <= ~100 ulp = 2e-14 relative apart: 1e-12
        # leaves ~50x margin on any CPU
        assert plant.applied_force == pytest.approx(expected, rel=1e-12)


def test_at_rest_the_train_waits_until_traction_beats_static_resistance_and_grade() -> None:
    p = Crh3Params()
    uphill = Route("up", 1e4, StepProfile.from_pairs([[0.0, 10.0]]))
    grade_force = p.mass * GRAVITY * 10.0 / 1000.0
    plant = Crh3Train(p, uphill)
    weak = grade_force + 0.5 * p.davis.a
    for k in range(20):
        plant.advance(to_ticks(k), to_ticks(1.0), {"force": weak})
    assert plant.v == 0.0 and plant.s == 0.0  # neither moves nor rolls back
    strong = grade_force + p.davis.a + 1e5
    for k in range(20, 30):
        plant.advance(to_ticks(k), to_ticks(1.0), {"force": strong})
    assert plant.v > 0.0


def _energy_imbalance(plant: Crh3Train, v0: float, s0: float) -> float:
    """W_traction - (dKE + dPE + W_resistance + W_brake) (J)."""
    d_ke = 0.5 * plant.p.effective_mass * (plant.v**2 - v0**2)
    d_pe = plant.p.mass * GRAVITY * (plant.height(plant.s) - plant.height(s0))
    return plant.work_traction - (d_ke + d_pe + plant.work_resistance + plant.work_brake)


def _crossing_bound(plant: Crh3Train, route: Route, v_max: float) -> float:
    """Error bound of the balance from the steps of the additional resistance.

    Between steps the augmented system (v, s, work integrals) is smooth and RK4's error is
    O(h^4) (far below this bound). Point mass: a step of ``dw`` N/kN in position makes the force
    jump by ``M g dw / 1000`` inside one sub-step, which RK4's stages place wrongly by at most
    the distance run in the sub-step, ``v h``: per crossing at most ``M g |dw| / 1000 v_max h``.
    A train of length ``l`` averages the steps: the force is continuous with a kink of slope
    ``M g dw / (1000 l)`` as the front and as the rear pass the step; within a sub-step it
    leaves the stages' polynomial by at most ``M g |dw| / 1000 v_max h / l`` over ``v_max h``:
    ``M g |dw| / 1000 (v_max h)^2 / l`` per kink, two kinks per step. Rounding: a few ulps of
    the works per sub-step.
    """
    p = plant.p
    add = StepProfile.sum(route.grade, route.curve_resistance, route.tunnel_resistance)
    jumps = np.abs(np.diff(add.values))
    crossed = add.starts[1:] <= plant.s
    per_crossing = float(np.sum(jumps[crossed])) * p.mass * GRAVITY / 1000.0 * v_max * p.max_step
    if p.length > 0.0:
        per_crossing *= 2.0 * v_max * p.max_step / p.length
    substeps = plant.t_ticks / to_ticks(p.max_step)
    return per_crossing + 16.0 * substeps * np.finfo(float).eps * plant.work_traction


@pytest.mark.parametrize("length", [0.0, 400.0])
def test_energy_account_closes_to_the_integration_bound(length: float) -> None:
    """Traction work = kinetic + potential energy + resistance losses + braking work, and
    eq. 9's outputs are those works with the efficiencies."""
    route = _route()
    p = dataclasses.replace(Crh3Params(), length=length)
    plant = Crh3Train(p, route)
    top = _run(plant, 800.0, 1.0)
    assert plant.held and plant.v == 0.0 and plant.s > 20000.0  # ran over every step, stopped
    v_max = 100.0  # m/s, above the run's top speed
    assert top < v_max
    bound = _crossing_bound(plant, route, v_max)
    imbalance = _energy_imbalance(plant, 0.0, 0.0)
    assert abs(imbalance) <= bound, (imbalance, bound)
    assert bound < 5e-4 * plant.work_traction  # a real check against the works (7.6 GJ)
    e = plant.outputs()
    # the eq. 9 terms are these very operations on the kept works (t - t0 = 800 s exactly in
    # integer ns), so IEEE arithmetic gives identical doubles on any CPU: compared exactly
    assert e["energy_traction"] == plant.work_traction / p.motor_efficiency
    assert e["energy_regen"] == p.regen_efficiency * plant.work_brake
    assert e["energy_aux"] == p.aux_power * 800.0
    assert e["energy_net"] == e["energy_traction"] - e["energy_regen"] + e["energy_aux"]
    assert plant.work_brake > 0.0 and plant.work_resistance > 0.0


def test_results_do_not_depend_on_the_communication_step() -> None:
    """Sub-steps lie on the absolute max_step grid: steps that are multiples of it give the
    same sub-steps, hence the same arithmetic and the same state."""
    route = _route()
    states = []
    for step in (1.0, 0.5, 0.2):
        plant = Crh3Train(Crh3Params(), route)
        _run(plant, 700.0, step)
        states.append((plant.v, plant.s, plant.work_traction, plant.work_brake, plant.force))
    assert states[0] == states[1] == states[2]


def test_outputs_are_consistent() -> None:
    p = Crh3Params()
    plant = Crh3Train(p, load_route("seed003_crh3"), v0=50.0, s0=1000.0)
    plant.advance(0, to_ticks(5.0), {"force": 2e5})
    out = plant.outputs()
    assert out["traction_limit"] == p.traction_limit(plant.v) > 0.0
    assert out["brake_limit"] == p.brake_limit(plant.v) > 0.0
    assert out["speed_limit"] == pytest.approx(350.0 * KMH)
    expected_a = (out["applied_force"] - p.davis.force(plant.v)) / p.effective_mass
    # a and power: a few roundings of O(1)-conditioned terms (no cancellation at 2e5 N traction
    # against ~5e4 N resistance): ~10 ulp, so rel=1e-12 has ~500x margin on any CPU
    assert out["a"] == pytest.approx(expected_a, rel=1e-12)  # level line at 1 km
    assert out["power"] == pytest.approx(out["applied_force"] * plant.v / p.motor_efficiency
                                         + p.aux_power, rel=1e-12)


def test_bad_parameters_are_refused() -> None:
    with pytest.raises(ValueError, match="motor_efficiency"):
        Crh3Train(dataclasses.replace(Crh3Params(), motor_efficiency=0.0), Route.flat())
    with pytest.raises(ValueError, match="v0"):
        Crh3Train(Crh3Params(), Route.flat(), v0=-1.0)


def test_fmu_serialized_state_reproduces_the_rest_of_the_run(built_fmus) -> None:
    """Crh3Train + Crh3Gpc (eco): serialize both states mid-run, finish, restore, rerun."""
    plant = FmuInstance(str(built_fmus["Crh3Train"].path), "plant", {"route": "seed003_crh3"})
    ctl = FmuInstance(str(built_fmus["Crh3Gpc"].path), "ctl", {"profile": "eco"})
    meas = ["v", "s", "traction_limit", "brake_limit"]

    def step(k: int) -> list[float]:
        ctl.set(meas, plant.get(meas))
        u = ctl.get(["force"])
        plant.set(["force"], u)
        plant.fmu.doStep(currentCommunicationPoint=float(k), communicationStepSize=1.0)
        ctl.fmu.doStep(currentCommunicationPoint=float(k), communicationStepSize=1.0)
        return plant.get(["v", "s", "energy_net"]) + u + ctl.get(["v_ref", "phase"])

    first, second = rerun_after_restore([plant, ctl], step, 30, 70)
    assert first == second
    assert first[-1][0] > 20.0  # accelerating along the profile
    for inst in (plant, ctl):
        inst.fmu.terminate()
        inst.fmu.freeInstance()
