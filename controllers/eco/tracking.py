"""Common interface of the seed-003 speed-profile trackers (GPC baseline, LMI robust MPC).

Every controller of this family is an :class:`EcoTracker` around a law; swapping one for the
other is one line of a scenario (the FMU name). Interface (units SI):

* **inputs** ``v`` (m/s, measured speed), ``s`` (m, measured position), ``traction_limit`` and
  ``brake_limit`` (N, >= 0: the plant's envelope at the present speed; ``plants.crh3``);
* **outputs** ``force`` (N, traction > 0, braking < 0: ``M (1 + gamma) u``), ``accel_demand``
  (m/s^2, the law's ``u``), ``v_ref`` (m/s) and ``a_ref`` (m/s^2): the profile's speed and
  acceleration now, ``s_ref`` (m) the profile's position now (time-indexed part),
  ``speed_error`` = v - v_ref (m/s), ``phase`` (1 accelerate, 2 run, 3 brake: Table 2's
  phases of the profile, for the energy-per-phase metrics);
* **parameters** ``profile`` (:data:`TRACKER_PROFILES`), ``optimum`` (the optimum's CSV for
  ``profile = "pmp"``: a bundled name in ``controllers/eco/data`` or a path), ``route``
  (bundled name or TOML path),
  ``scheduled_time`` (s, -1: the route's ``scheduled_time_s``), the train data the profile is
  planned with and ``u`` is scaled by (``mass``, ``rotating_mass_factor``), the limits
  (``accel_min``/``accel_max`` -1/1 m/s^2, ``cruise_speed`` V_act 330 km/h, ``limit_speed``
  V_lim 350 km/h), the profile's ``brake_decel`` and ``traction_share``, ``position_gain``,
  ``stop_speed``, ``hold_accel``, ``sample_time`` (T = 1 s), then the law's own.

The law (a subclass) sees the train as ``y = v`` (m/s) driven by ``u`` (m/s^2, force per
effective mass) and implements :meth:`EcoTracker.law_control` (``y``, the references
``refs[j] = r(k + 1 + j)``, ``j = 0..horizon-1``, and the input box ``lo <= u <= hi``) and
:meth:`EcoTracker.law_hold` (the train is held at the stop with ``u``; a law that learns can
update its data). ``horizon`` (class attribute or property) is the number of references the
law wants.

Reference (:mod:`controllers.common.speed_profiles`), ``t`` counted from the run's start
(departure): before the profile's final braking point the profile is followed *in time*
(distance-time tracking, which keeps the arrival time): ``refs[j] = v_p(t + (j+1) T) +
c``, with the position correction ``c = position_gain (s_p(t) - s)`` limited to
``+-max_correction``, capped to ``[0, V_lim]``; from the final braking point on, *in distance*
(so the train stops at the stop point whatever its delay): ``refs[j] = max(v_p(s) + a_p(s)
(j+1) T, 0)``. The input box is the envelope and the comfort limit: ``lo = max(accel_min,
-brake_limit / M_eff)``, ``hi = min(accel_max, traction_limit / M_eff)``. At the stop point
(profile speed 0) and below ``stop_speed`` the train is held with ``hold_accel``.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from controllers.common.speed_profiles import (
    PHASE_BRAKE,
    PHASE_RUN,
    PROFILE_KINDS,
    ProfileSettings,
    SpeedProfile,
    generate,
    read_optimum,
)
from cosim.fmu.declare import Checked, Declared, Var, build, param, sample_time
from cosim.fmu.state import StatefulCore
from plants.crh3 import Crh3Params
from plants.resistance import KMH
from plants.route import load_route, route_parameter, routes_dir_in


@dataclass(frozen=True)
class EcoTrackingParams(Checked):
    """The interface part shared by the seed-003 controllers."""

    mass: float = param(980e3, "kg", "train mass M (Table 1)", min=1.0)
    rotating_mass_factor: float = param(0.06, "1", "gamma: force = M (1 + gamma) u", min=0.0)
    accel_min: float = param(-1.0, "m/s2", "a_min: comfort limit on u (sec. 4)", max=0.0)
    accel_max: float = param(1.0, "m/s2", "a_max: comfort limit on u (sec. 4)", min=0.0)
    cruise_speed: float = param(330.0 * KMH, "m/s", "V_act: cruising speed of the profiles",
                                min=0.0)
    limit_speed: float = param(350.0 * KMH, "m/s", "V_lim: highest speed of the profiles",
                               min=0.0)
    brake_decel: float = param(0.5, "m/s2", "service braking of the profiles to the stop",
                               min=1e-3, max=1.0)
    traction_share: float = param(0.9, "1", "share of the traction envelope the profiles plan "
                                  "with (the rest is the controller's headroom)", min=0.01,
                                  max=1.0)
    position_gain: float = param(0.02, "1/s", "position correction c = gain (s_ref - s) of "
                                 "the time-indexed reference", min=0.0)
    max_correction: float = param(2.0, "m/s", "largest |c|", min=0.0)
    stop_speed: float = param(0.3, "m/s", "below this speed at the stop point the holding "
                              "brake is applied", min=0.0)
    hold_accel: float = param(-0.5, "m/s2", "brake demand holding the train at the stop",
                              max=0.0)
    sample_time: float = sample_time(1.0)

    # the fields the profiles are planned with (:meth:`train`, :meth:`settings`)
    planning_fields: ClassVar[tuple[str, ...]] = (
        "mass", "rotating_mass_factor", "cruise_speed", "limit_speed", "accel_max",
        "brake_decel", "traction_share")

    def train(self) -> Crh3Params:
        """The nominal train the profiles are planned on (plant defaults, this mass)."""
        return replace(Crh3Params(), mass=self.mass,
                       rotating_mass_factor=self.rotating_mass_factor)

    def settings(self) -> ProfileSettings:
        return ProfileSettings(cruise_speed=self.cruise_speed, limit_speed=self.limit_speed,
                               accel_max=min(self.accel_max, 1.0),
                               brake_decel=self.brake_decel,
                               traction_share=self.traction_share)

    @property
    def effective_mass(self) -> float:
        return self.mass * (1.0 + self.rotating_mass_factor)


PMP = "pmp"  # the profile read from an optimum of the maximum principle (cosim optimal)
TRACKER_PROFILES = (*PROFILE_KINDS, PMP)


def optimum_dir_in(data_dir: Path) -> Path:
    """The bundled optimum folder under an FMU's data folder (or the project tree)."""
    return Path(data_dir) / "controllers" / "eco" / "data"


PROFILE_VARS: tuple[Var, ...] = (
    Var("profile", "parameter", "conventional", description="target profile: "
        "'conventional' (accelerate, cruise at V_act, brake), 'eco' (accelerate, coast, "
        "re-accelerate, ..., brake), 'cruise' (accelerate, cruise at the constant speed "
        "that meets the schedule, brake), 'fixed_family' (maximum traction, speed holding "
        "(by braking downhill), coasting, service braking: the best of that family for the "
        "schedule) or 'pmp' (the energy optimum of the maximum principle, read from the "
        "file 'optimum')"),
    Var("optimum", "parameter", "seed003_crh3_optimum_service_brake", description="the "
        "optimum that profile 'pmp' follows: a CSV written by cosim optimal, by bundled name "
        "(controllers/eco/data/<name>.csv) or path"),
    route_parameter("seed003_crh3", "the profile's line"),
    Var("scheduled_time", "parameter", -1.0, "s", "scheduled running time the eco, "
        "cruise and optimal profiles use up (-1: the route's scheduled_time_s)"),
)
TRACKER_INPUTS: tuple[Var, ...] = (
    Var.input("v", "m/s", "measured speed"),
    Var.input("s", "m", "measured position"),
    Var.input("traction_limit", "N", "largest traction force now (>= 0)"),
    Var.input("brake_limit", "N", "largest brake force now (>= 0)"),
)
TRACKER_OUTPUTS: tuple[Var, ...] = (
    Var.output("force", "N", "force demand M (1 + gamma) u (traction > 0)"),
    Var.output("accel_demand", "m/s2", "u: force demand per effective mass"),
    Var.output("v_ref", "m/s", "profile speed now"),
    Var.output("a_ref", "m/s2", "profile acceleration now"),
    Var.output("s_ref", "m", "profile position now (time-indexed)"),
    Var.output("speed_error", "m/s", "v - v_ref"),
    Var.output("phase", "1", "Table 2 phase of the profile: 1 accelerate, 2 run, 3 brake"),
)


def plan_profile(track: EcoTrackingParams, values: dict[str, Any], data_dir: Path
                 ) -> SpeedProfile:
    """The target profile of the :data:`PROFILE_VARS` in ``values`` (``profile``,
    ``optimum``, ``route``, ``scheduled_time``) for the train and limits of ``track``; the
    bundled route and optimum files under ``data_dir`` (the FMU's resources or the project
    tree)."""
    kind = values["profile"]
    if kind not in TRACKER_PROFILES:
        raise ValueError(f"profile = {kind!r} must be one of {TRACKER_PROFILES}")
    route = load_route(values["route"], routes_dir_in(data_dir))
    scheduled = float(values["scheduled_time"])
    if kind == PMP:
        name = str(values["optimum"])
        path = Path(name) if Path(name).suffix else optimum_dir_in(data_dir) / f"{name}.csv"
        return read_optimum(path, route, scheduled if scheduled > 0 else None,
                            track.settings())
    return generate(kind, route, scheduled if scheduled > 0 else None, track.train(),
                    track.settings())


class EcoTracker(StatefulCore, Declared):
    """Base of the seed-003 trackers; a subclass sets ``params_class`` (a dataclass with the
    group ``track`` (:class:`EcoTrackingParams`, prefix "") and its law's group), ``horizon``
    and the two law methods."""

    horizon: ClassVar[int] = 1
    tracker_state: ClassVar[tuple[str, ...]] = ("force", "u", "v_ref", "a_ref", "s_ref",
                                                "speed_error", "phase", "holding")
    setup_vars = PROFILE_VARS
    input_vars = TRACKER_INPUTS
    output_vars = TRACKER_OUTPUTS

    @classmethod
    def from_parameters(cls, values: dict[str, Any], data_dir: Path,
                        t0: float = 0.0) -> EcoTracker:
        params = build(cls.params_class(), values)
        profile = plan_profile(params.track, values, data_dir)
        return cls.build_core(params, profile, t0, data_dir)

    @classmethod
    def build_core(cls, params: Any, profile: SpeedProfile, t0: float,
                   data_dir: Path) -> EcoTracker:
        """The core from its parameters and profile; a law with bundled data reads it from
        ``data_dir`` (the FMU's resources or the project tree)."""
        return cls(params, profile, t0)

    def __init__(self, params: Any, profile: SpeedProfile, t0: float = 0.0) -> None:
        params.check()
        self.p = params
        self.track: EcoTrackingParams = params.track
        self.profile = profile
        self.t0 = float(t0)
        self.m_eff = self.track.effective_mass
        self.force = 0.0
        self.u = 0.0
        (self.v_ref, self.a_ref, self.s_ref, self.speed_error) = (0.0, 0.0, 0.0, 0.0)
        self.phase = 1
        self.holding = False

    # -- shared machinery -------------------------------------------------------------------
    def input_box(self, traction_limit: float, brake_limit: float) -> tuple[float, float]:
        """(lo, hi) of ``u`` (m/s^2): the envelope and the comfort limits."""
        tr = self.track
        hi = min(tr.accel_max, max(traction_limit, 0.0) / self.m_eff)
        lo = max(tr.accel_min, -max(brake_limit, 0.0) / self.m_eff)
        return min(lo, hi), hi

    def references(self, t: float, s: float, n: int) -> np.ndarray:
        """``refs[j] = r(k + 1 + j)`` (m/s), j < n; sets v_ref, a_ref, s_ref and phase."""
        prof, tr = self.profile, self.track
        T = tr.sample_time
        tau = t - self.t0
        j = np.arange(1, n + 1)
        if s >= prof.brake_start_position:  # final braking: in distance
            v_d, a_d = prof.at_position(s)
            self.v_ref, self.a_ref = v_d, a_d
            self.s_ref = prof.at_time(tau)[0]
            self.phase = PHASE_BRAKE
            return np.maximum(v_d + a_d * j * T, 0.0)
        s_p, v_p, a_p = prof.at_time(tau)
        self.v_ref, self.a_ref, self.s_ref = v_p, a_p, s_p
        self.phase = min(prof.phase_at_time(tau), PHASE_RUN)
        c = float(np.clip(tr.position_gain * (s_p - s), -tr.max_correction,
                          tr.max_correction))
        future = np.array([prof.at_time(tau + k * T)[1] for k in j])
        return np.clip(future + c, 0.0, tr.limit_speed)

    def compute(self, t: float, inputs: dict[str, float]) -> tuple[dict[str, float], int]:
        v, s = float(inputs["v"]), float(inputs["s"])
        lo, hi = self.input_box(float(inputs["traction_limit"]), float(inputs["brake_limit"]))
        refs = self.references(t, s, self.horizon)
        tr = self.track
        self.holding = (self.phase == PHASE_BRAKE and self.v_ref <= 0.0
                        and v < tr.stop_speed)
        if self.holding:
            u = min(max(tr.hold_accel, lo), hi)
            self.law_hold(v, u)
        else:
            u = float(self.law_control(v, refs, lo, hi))
        self.u = u
        self.force = self.m_eff * u
        self.speed_error = v - self.v_ref
        return self.outputs(), 1

    def outputs(self) -> dict[str, float]:
        return {"force": self.force, "accel_demand": self.u, "v_ref": self.v_ref,
                "a_ref": self.a_ref, "s_ref": self.s_ref, "speed_error": self.speed_error,
                "phase": float(self.phase)}

    # -- the law ----------------------------------------------------------------------------
    def law_control(self, y: float, refs: np.ndarray, lo: float, hi: float) -> float:
        """``u`` (m/s^2) in ``[lo, hi]`` for measured ``y`` (m/s) and references ``refs``."""
        raise NotImplementedError

    def law_hold(self, y: float, u: float) -> None:
        """The train is held at the stop with ``u`` (no law output is used)."""
