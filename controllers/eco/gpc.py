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
from controllers.eco.tracking import EcoTracker, EcoTrackingParams, SpeedProfile
from controllers.robust.rmpc import load_model_set, models_dir_in
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
