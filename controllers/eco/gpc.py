"""GPC baseline of seed 003 (sec. 4: compared with the robust MPC on the eco profile).

The GPC core of seed 001 (:class:`controllers.common.gpc.Gpc`, shared, not copied) with one
output ``y = v`` (m/s) and one input ``u`` (m/s^2, force per effective mass): an incremental
ARX model identified on line by RLS with forgetting, horizons ``Ny``/``Nu``. The references
over the horizon are :meth:`controllers.eco.tracking.EcoTracker.references`; ``u`` is clipped
to the envelope and comfort box, and the clipped value is what the model remembers.
``b_init`` = T = 1 s: ``dv ~ T du`` of a mass driven by ``u``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from controllers.common.gpc import Gpc, GpcParams
from controllers.eco.tracking import EcoTracker, EcoTrackingParams, SpeedProfile
from cosim.fmu.declare import group


@dataclass(frozen=True)
class Crh3GpcParams:
    """Interface part and the GPC's parameters (seed 001's Ny = 3, Nu = 2; b_init = T)."""

    track: EcoTrackingParams = group(EcoTrackingParams(), "")
    gpc: GpcParams = group(GpcParams(b_init=1.0, control_weight=1.0), "")


class Crh3Gpc(EcoTracker):
    """GPC tracker of the seed-003 profiles."""

    params_class = Crh3GpcParams
    state_fields = (*EcoTracker.tracker_state, "gpc")

    def __init__(self, params: Crh3GpcParams, profile: SpeedProfile, t0: float = 0.0) -> None:
        super().__init__(params, profile, t0)
        self.gpc = Gpc(params.gpc, 1)

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
