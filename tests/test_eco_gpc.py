"""Seed 003 trackers: the common interface (controllers/eco/tracking.py) and the GPC baseline
(controllers/eco/gpc.py, sharing controllers/common/gpc.py with seed 001)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from controllers.common import speed_profiles as sp
from controllers.eco.gpc import Crh3Gpc, Crh3GpcParams
from cosim.fmu.closed_loop import closed_loop
from plants.crh3 import Crh3Params, Crh3Train
from plants.route import load_route

ROUTE = load_route("seed003_crh3")


def _controller(kind: str = "eco") -> Crh3Gpc:
    params = Crh3GpcParams()
    prof = sp.generate(kind, ROUTE, None, params.track.train(), params.track.settings())
    return Crh3Gpc(params, prof)


def _closed_loop(kind: str, t_end: float | None = None) -> tuple[np.ndarray, Crh3Gpc]:
    """Plant and controller cores, T = 1 s; rows (t, v, s, v_ref, u, phase)."""
    ctl = _controller(kind)
    plant = Crh3Train(Crh3Params(), ROUTE)
    t_end = ctl.profile.arrival_time + 30.0 if t_end is None else t_end
    loop = closed_loop(plant, ctl, float(int(t_end)), 1.0,
                       inputs=("v", "s", "traction_limit", "brake_limit"), commands=("force",))
    assert loop.event[:-1].all()  # periodic: an event every second
    rows = np.column_stack([loop.time, loop.plant["v"], loop.plant["s"], loop.controller["v_ref"],
                            loop.controller["accel_demand"], loop.controller["phase"]])
    return rows[:-1], ctl


def test_input_box_is_the_envelope_and_the_comfort_limit() -> None:
    ctl = _controller()
    m = ctl.m_eff
    assert ctl.input_box(1e9, 1e9) == (-1.0, 1.0)
    lo, hi = ctl.input_box(0.2 * m, 0.3 * m)
    assert (lo, hi) == pytest.approx((-0.3, 0.2), rel=1e-12)
    assert ctl.input_box(0.0, 0.0) == (0.0, 0.0)


def test_references_follow_time_then_distance_in_the_final_braking() -> None:
    ctl = _controller()
    prof = ctl.profile
    s_p, v_p, _ = prof.at_time(600.0)
    ahead = ctl.references(600.0, s_p + 50.0, 3)  # 50 m ahead: slower, by the gain
    on = ctl.references(600.0, s_p, 3)
    assert on[0] == pytest.approx(prof.at_time(601.0)[1], rel=1e-12)
    assert on - ahead == pytest.approx(np.full(3, ctl.track.position_gain * 50.0), rel=1e-9)
    assert ctl.phase == sp.PHASE_RUN
    s_brake = prof.brake_start_position + 1000.0
    refs = ctl.references(0.0, s_brake, 3)  # in the final braking: by position, any time
    v_d, a_d = prof.at_position(s_brake)
    assert refs == pytest.approx(v_d + a_d * np.arange(1, 4), rel=1e-12)
    assert ctl.phase == sp.PHASE_BRAKE and a_d == pytest.approx(-0.5, rel=1e-9)


def test_gpc_tracks_the_eco_profile_arrives_on_time_and_stops_at_the_point() -> None:
    rows, ctl = _closed_loop("eco")
    t, v, s, v_ref, u, phase = rows.T
    err_kmh = (v - v_ref) * 3.6
    assert np.sqrt(np.mean(err_kmh**2)) < 0.5  # km/h
    assert np.max(np.abs(err_kmh[t > 20])) < 3.0  # transients at the mode switches
    assert np.all(np.abs(u) <= 1.0 + 1e-12)
    arrival = t[np.nonzero(v > 1e-3)[0][-1] + 1]
    assert abs(arrival - ROUTE.scheduled_time_s) <= 5.0  # Delta T_max
    assert abs(s[-1] - ROUTE.length_m) <= 0.5  # Delta l_max
    assert list(np.unique(phase)) == [1.0, 2.0, 3.0] and np.all(np.diff(phase) >= 0)


def test_held_at_the_stop_the_gpc_keeps_its_data() -> None:
    ctl = _controller("conventional")
    ctl.compute(0.0, {"v": 0.0, "s": 0.0, "traction_limit": 6e5, "brake_limit": 8e5})
    out, _ = ctl.compute(5000.0, {"v": 0.0, "s": ROUTE.length_m, "traction_limit": 6e5,
                                  "brake_limit": 8e5})
    assert ctl.holding and out["accel_demand"] == ctl.track.hold_accel
    assert out["force"] == pytest.approx(ctl.m_eff * ctl.track.hold_accel, rel=1e-12)
    assert ctl.gpc.u_prev[0] == ctl.track.hold_accel


@pytest.mark.slow
def test_scenarios_follow_their_profiles_on_time_and_energy(tmp_path) -> None:
    """The shipped GPC scenarios through the master: on time and at the stop point (sec. 4
    limits), phases sum to the total, and the traction energy the plant drew is the planned
    profile's nominal traction work (sp.traction_work) / eta_M: the energy comes from the
    profile, so any ranking of profiles is the ranking of their planned work."""
    from cosim.run.simulate import run_scenario

    eta_m = Crh3Params().motor_efficiency  # the scenarios keep the default
    for kind in sp.PROFILE_KINDS:  # the fixed family: the optimal rows' scenario, overridden
        stem = "optimal" if kind == "fixed_family" else kind
        run_scenario(f"seed003_crh3_gpc_{stem}", out_dir=tmp_path / kind,
                     overrides={"controller.profile": kind} if stem != kind else None)
        summary = json.loads((tmp_path / kind / "summary.json").read_text())
        assert abs(summary["arrival_time_error_s"]) <= 5.0
        assert abs(summary["stop_error_m"]) <= 0.5
        parts = sum(summary[f"energy_{p}_mj"] for p in ("accelerate", "run", "brake"))
        assert parts == pytest.approx(summary["energy_net_mj"], rel=1e-9)
        planned = sp.traction_work(sp.generate(kind, ROUTE), ROUTE) / eta_m / 1e6
        # closed loop: tracking errors of <= 3 km/h and the 0.5 s force lag cost a little
        assert summary["energy_traction_mj"] == pytest.approx(planned, rel=0.03)


def test_the_identified_start_is_the_lmi_mpcs_departure_model_in_gpc_units() -> None:
    """``model_start = "identified"`` starts the RLS model from the lowest-speed ARX model of
    the robust MPC's set, dv(k) = a dv(k-1) + b' du(k-1) with b' = b 100 (1 + gamma) / (3.6 g)
    (km/h per daN/kN to m/s per m/s^2): one sample of each model gives the same speed change;
    "cold" keeps A = 0, B = b_init; another name is refused."""
    import dataclasses

    from controllers.robust.rmpc import load_model_set
    from plants.route import GRAVITY

    arx = load_model_set("identified")
    params = Crh3GpcParams()
    ctl = Crh3Gpc(params, _controller().profile)
    a, b = ctl.gpc.theta[0]
    assert a == arx.a[0]
    gamma = params.track.rotating_mass_factor
    du = 0.1  # m/s^2, one input step
    assert b * du == pytest.approx(arx.b[0] * du * 100.0 * (1.0 + gamma) / GRAVITY / 3.6,
                                   rel=1e-12)
    cold = dataclasses.replace(params, start=dataclasses.replace(params.start,
                                                                   model_start="cold"))
    assert Crh3Gpc(cold, ctl.profile).gpc.theta.tolist() == [[0.0, params.gpc.b_init]]
    bad = dataclasses.replace(params, start=dataclasses.replace(params.start,
                                                                  model_start="warm"))
    with pytest.raises(ValueError, match="model_start"):
        Crh3Gpc(bad, ctl.profile)
