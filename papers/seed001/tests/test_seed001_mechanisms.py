"""Seed 001's mechanisms, each on every law it applies to: the comfort clip alike for the four
laws, anti-windup of the sliding laws' sums, null-space force sharing, ISMPC with and without
its QP, GPC's plan / apply split, and the paper metrics of papers/seed001/metrics.py."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from controllers.common.ffdl import truncated_gain
from controllers.common.gpc import Gpc, GpcParams
from controllers.datadriven.emu_control import EmuGpc, EmuIsmc, EmuIsmpc, EmuMfac
from controllers.datadriven.laws import (
    GpcLaw,
    GpcLawParams,
    Ismc,
    IsmcParams,
    Ismpc,
    IsmpcParams,
    SurfaceParams,
    null_space_share,
)
from cosim.papers import paper_metrics
from plants.route import load_reference

comfort = paper_metrics("seed001").comfort  # papers/seed001/metrics.py
unit_tracking_si = paper_metrics("seed001").unit_tracking_si

CORES = (EmuMfac, EmuIsmc, EmuIsmpc, EmuGpc)
CRUISE_S = 100_000.0  # m: the seed-001 reference cruises at 300 km/h here (a_ref = 0)


def _unit_accels(cls, accel_max: float, samples: int = 20) -> np.ndarray:
    """Each unit's commanded force per unit mass (m/s2) over ``samples`` samples of a train
    50 km/h below the reference, with an envelope far above any comfort limit."""
    params = cls.params_class()
    params = dataclasses.replace(params, drive=dataclasses.replace(params.drive,
                                                                  accel_max=accel_max))
    core = cls(params, load_reference("jinan_xuzhou_east_reference"), 3)
    v = core.profile.speed(CRUISE_S) - 50.0 / 3.6
    inputs = {"s": CRUISE_S, **{f"v[{i}]": v for i in (1, 2, 3)},
              **{f"traction_limit[{i}]": 1e9 for i in (1, 2, 3)},
              **{f"brake_limit[{i}]": 1e9 for i in (1, 2, 3)}}
    out = []
    for k in range(samples):
        forces, _ = core.compute(float(k), inputs)
        out.append([forces[f"force[{i}]"] / core.unit_mass for i in (1, 2, 3)])
    return np.array(out)


@pytest.mark.parametrize("cls", CORES, ids=lambda c: c.__name__)
def test_the_comfort_clip_is_applied_alike_to_every_law(cls) -> None:
    clipped = _unit_accels(cls, 1.0)
    assert np.abs(clipped).max() <= 1.0 + 1e-12  # a clip: exact up to one rounding
    free = _unit_accels(cls, 100.0)  # the clip removed: the law asks for more than 1 m/s2
    assert np.abs(free).max() > 1.0


def _integrator_loop(law, steps: int, hi: float) -> tuple[np.ndarray, np.ndarray]:
    """Three free units ``y(t+1) = y(t) + u(t)`` (Phi_2 = I) chasing a ramp of 0.5 per sample
    with inputs boxed to ``[-hi, hi]``: every unit saturates upwards. Returns E and u."""
    y = np.zeros(3)
    lo_b, hi_b = np.full(3, -hi), np.full(3, hi)
    Es, us = [], []
    for t in range(steps):
        u = law.step(y, np.full(3, 0.5 * t), np.full(3, 0.5 * (t + 1)), lo_b, hi_b)
        Es.append(law.E.copy())
        us.append(u.copy())
        y = y + u
    return np.array(Es), np.array(us)


@pytest.mark.parametrize("law_cls,params_cls", [(Ismc, IsmcParams), (Ismpc, IsmpcParams)])
def test_anti_windup_holds_the_sums_while_every_unit_saturates(law_cls, params_cls) -> None:
    def law(anti_windup: bool):
        surface = SurfaceParams(anti_windup=anti_windup, share_gain=0.0, common_integral=0.0)
        return law_cls(dataclasses.replace(params_cls(), surface=surface), 3)

    E_aw, u_aw = _integrator_loop(law(True), 40, 0.1)
    E_free, _ = _integrator_loop(law(False), 40, 0.1)
    saturated = np.all(u_aw >= 0.1 - 1e-9, axis=1)
    first = int(np.argmax(saturated))
    assert saturated[first:].all()  # once saturated, it stays so (the ramp runs away)
    # with anti-windup E never moves again; without, it integrates the growing error
    assert np.array_equal(E_aw[first:], np.broadcast_to(E_aw[first], E_aw[first:].shape))
    assert np.all(np.abs(E_free[-1]) > 10.0 * np.abs(E_aw[-1]) + 1.0)


def test_null_space_share_moves_only_the_split_between_units() -> None:
    M = np.full((3, 3), 0.7 / 3)  # rank one: every unit's force moves every speed alike
    gain = truncated_gain(M, 1e-2, 0.1)
    u = np.array([1.0, 0.0, -0.4])
    move = null_space_share(u, gain.M, gain.K, 0.5)
    assert np.abs(gain.M @ move).max() <= 1e-12  # no effect on the modelled outputs
    # u's departure from its mean is orthogonal to the common mode: half of it is removed
    assert move == pytest.approx(0.5 * (u - u.mean()), abs=1e-12)
    assert np.abs(null_space_share(np.full(3, 0.3), gain.M, gain.K, 0.5)).max() <= 1e-15


@pytest.mark.parametrize("constraints", ["qp", "clip"])
def test_ismpc_without_its_qp_clips_like_the_other_laws(constraints: str) -> None:
    law = Ismpc(IsmpcParams(constraints=constraints), 3)
    _, u = _integrator_loop(law, 40, 0.1)
    assert np.all(np.abs(u) <= 0.1 + 1e-12)
    assert (law.qp_solves > 0) == (constraints == "qp")


def test_ismpc_rejects_an_unknown_constraint_handling() -> None:
    with pytest.raises(ValueError, match="constraints = 'box'"):
        Ismpc(IsmpcParams(constraints="box"), 3)


def test_gpc_law_without_sharing_is_the_shared_gpc_core() -> None:
    params = GpcLawParams(share_gain=0.0)
    law, core = GpcLaw(params, 3), Gpc(params.gpc, 3)
    rng = np.random.default_rng(3)
    lo, hi = np.full(3, -1.0), np.full(3, 1.0)
    y = np.zeros(3)
    for t in range(30):
        core.observe(y)
        y_r, y_next = 0.2 * t, 0.2 * (t + 1)
        j = np.arange(1, params.gpc.Ny + 1)[:, None]  # the law's linear extrapolation
        u_core = core.control(np.maximum(y_r + j * (y_next - y_r), 0.0) * np.ones((1, 3)),
                              lo, hi)
        u_law = law.step(y, np.full(3, y_r), np.full(3, y_next), lo, hi)
        assert np.array_equal(u_law, u_core)
        y = y + 0.5 * u_core + 0.01 * rng.standard_normal(3)


def test_gpc_plan_is_control_before_the_clip() -> None:
    a, b = Gpc(GpcParams(), 2), Gpc(GpcParams(), 2)
    refs = np.full((3, 2), 4.0)
    for g in (a, b):
        g.observe(np.zeros(2))
    planned = a.plan(refs)
    assert np.all(np.abs(planned) > 0.5)  # the box below binds
    assert np.array_equal(b.control(refs, np.full(2, -0.5), np.full(2, 0.5)),
                          np.clip(planned, -0.5, 0.5))


def test_unit_tracking_si_of_a_constant_error() -> None:
    t = np.linspace(0.0, 100.0, 101)
    ref = np.full(t.size, 20.0)
    speeds = np.column_stack([ref + 0.5, ref - 0.5, ref + 1.0])
    got = unit_tracking_si(t, speeds, ref)
    assert got["unit_mse_mps2"] == pytest.approx((0.25 + 0.25 + 1.0) / 3, rel=1e-12)
    assert got["unit_iae_m"] == pytest.approx(100.0 * (0.5 + 0.5 + 1.0) / 3, rel=1e-12)


def test_comfort_counts_the_time_any_unit_is_above_the_limit() -> None:
    t = np.arange(0.0, 10.0, 0.5)  # 20 samples, 0.5 s apart
    a = np.zeros((t.size, 3))
    a[4:8, 2] = -1.2  # unit 3 above the limit for 4 samples = 2 s
    a[10, 0] = 0.9
    got = comfort(t, a, 1.0)
    assert got["unit_max_abs_accel_mps2"] == 1.2 and got["comfort_exceeded"] is True
    assert got["comfort_exceedance_s"] == pytest.approx(2.0, rel=1e-12)
    assert comfort(t, a, 1.5)["comfort_exceeded"] is False
