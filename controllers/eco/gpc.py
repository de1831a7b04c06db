"""GPC baseline of seed 003 (sec. 4: compared with the robust MPC on the eco profile).

The GPC core of seed 001 (:class:`controllers.common.gpc.Gpc`, shared, not copied) with one
output ``y = v`` (m/s) and one input ``u`` (m/s^2, force per effective mass): an incremental
ARX model identified on line by RLS with forgetting, horizons ``Ny``/``Nu``. The references
over the horizon are :meth:`controllers.eco.tracking.EcoTracker.references`; ``u`` is clipped
to the envelope and comfort box, and the clipped value is what the model remembers.
Start of the RLS model (``model_start``): ``"identified"`` (the default) starts from the ARX
model the robust MPC uses at departure (the lowest-speed model of the identified set,
:func:`controllers.robust.rmpc.load_model_set`), in increments ``dv(k) = a dv(k-1) +
b' du(k-1)`` with ``b' = b 100 (1 + gamma) / (3.6 g)`` (km/h per daN/kN to m/s per m/s^2), so
both trackers start from the same information; ``"cold"`` starts from ``A_1 = 0``,
``B_1 = b_init`` = T = 1 s (``dv ~ T du`` of a mass driven by ``u``, seed 001's start).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from controllers.common.gpc import Gpc, GpcParams
from controllers.eco.tracking import (
    PMP,
    PROFILE_KINDS,
    PROFILE_VARS,
    EcoTracker,
    EcoTrackingParams,
    SpeedProfile,
    optimum_dir_in,
    plan_profile,
)
from controllers.robust.rmpc import load_model_set, models_dir_in
from cosim.fmu.c_text import ShippedValues
from cosim.fmu.declare import Checked, group, param
from plants.route import GRAVITY

MODEL_STARTS = ("identified", "cold")


@dataclass(frozen=True)
class GpcStartParams(Checked):
    """Where the GPC's on-line model starts."""

    model_start: str = param("identified", description='start of the RLS model: '
                             '"identified" (the robust MPC\'s ARX model at departure) or '
                             '"cold" (A_1 = 0, B_1 = b_init)', choices=MODEL_STARTS)


@dataclass(frozen=True)
class Crh3GpcParams(Checked):
    """Interface part and the GPC's parameters (seed 001's Ny = 3, Nu = 2; b_init = T)."""

    track: EcoTrackingParams = group(EcoTrackingParams(), "")
    gpc: GpcParams = group(GpcParams(b_init=1.0, control_weight=1.0), "")
    start: GpcStartParams = group(GpcStartParams(), "")


class Crh3Gpc(EcoTracker):
    """GPC tracker of the seed-003 profiles."""

    params_class = Crh3GpcParams
    state_fields = (*EcoTracker.tracker_state, "gpc")

    @classmethod
    def native_data(cls, identifier: str, shipped: ShippedValues) -> dict[str, str]:
        """The build-time data of the native twin (:mod:`cosim.build.native`): the target
        profiles, planned by the Python planner (:func:`controllers.eco.tracking.plan_profile`)
        with the declared defaults on the route the ``route`` parameter names by default,
        ``resources/eco_profiles/<route>/<profile>.profile`` per generated kind
        (``PROFILE_KINDS``) and ``resources/eco_profiles/<route>/pmp/<optimum>.profile`` per
        bundled optimum. Each holds lines ``<parameter> <value>``: the values it was planned
        with (``EcoTrackingParams.planning_fields`` for a generated kind, and
        ``scheduled_time``), which the native FMU requires; the phase boundaries
        ``accelerate_end_time``, ``brake_start_position``, ``brake_start_time``; then ``points
        n`` and n lines ``s v t accel`` (m, m/s, s, m/s^2 of the step from the point). And
        ``resources/eco_profiles/identified.arx``: ``a`` and ``b`` of the identified ARX model
        at departure (the model set's first, ARX units) and the ``gravity`` of the unit
        change. %.17g via repr: exact."""
        project = Path(__file__).resolve().parents[2]
        track = EcoTrackingParams()
        defaults = {v.name: v.start for v in PROFILE_VARS}
        route = str(defaults["route"])
        scheduled = f"scheduled_time {float(defaults['scheduled_time'])!r}"
        planned = [f"{name} {float(getattr(track, name))!r}" for name in track.planning_fields]
        wanted = [(f"{kind}.profile", {"profile": kind}, [*planned, scheduled])
                  for kind in PROFILE_KINDS]
        wanted += [(f"pmp/{csv.stem}.profile", {"profile": PMP, "optimum": csv.stem},
                    [scheduled])
                   for csv in sorted(optimum_dir_in(project).glob("*.csv"))]
        tables = {}
        for rel, chosen, settings in wanted:
            profile = plan_profile(track, {**defaults, **chosen}, project)
            rows = [f"{float(a)!r} {float(b)!r} {float(c)!r} {float(d)!r}"
                    for a, b, c, d in zip(profile.s.tolist(), profile.v.tolist(),
                                          profile.t.tolist(), profile.accel.tolist())]
            tables[f"resources/eco_profiles/{route}/{rel}"] = "\n".join([
                f"# seed-003 target profile {profile.kind} of route {route} (generated): the "
                "parameters it is planned with, its phase boundaries, then s v t accel",
                *settings, f"accelerate_end_time {profile.accelerate_end_time!r}",
                f"brake_start_position {profile.brake_start_position!r}",
                f"brake_start_time {profile.brake_start_time!r}", f"points {len(rows)}", *rows,
                ""])
        models = load_model_set("identified")
        tables["resources/eco_profiles/identified.arx"] = (
            "# the identified ARX model at departure (a, b) and the gravity of the unit change\n"
            f"a {float(models.a[0])!r}\nb {float(models.b[0])!r}\n"
            f"gravity {float(GRAVITY)!r}\n")
        return tables

    @classmethod
    def build_core(cls, params: Crh3GpcParams, profile: SpeedProfile, t0: float,
                   data_dir: Path) -> Crh3Gpc:
        return cls(params, profile, t0, data_dir)

    def __init__(self, params: Crh3GpcParams, profile: SpeedProfile, t0: float = 0.0,
                 data_dir: Path | None = None) -> None:
        super().__init__(params, profile, t0)
        start = params.start.model_start
        gpc = params.gpc
        if start == "identified":
            models = load_model_set("identified",
                                    None if data_dir is None else models_dir_in(data_dir))
            to_unit = 100.0 * (1.0 + params.track.rotating_mass_factor) / GRAVITY
            gpc = replace(gpc, a_init=models.a[0], b_init=models.b[0] * to_unit / 3.6)
        self.gpc = Gpc(gpc, 1)

    @property
    def horizon(self) -> int:  # type: ignore[override]
        return self.p.gpc.Ny

    def law_control(self, y: float, refs: np.ndarray, lo: float, hi: float) -> float:
        self.gpc.observe(np.array([y]))
        u = self.gpc.control(refs[:, None], np.array([lo]), np.array([hi]))
        return float(u[0])

    def law_hold(self, y: float, u: float) -> None:
        self.gpc.observe(np.array([y]), adapt=False)
        self.gpc.applied(np.array([u]))
