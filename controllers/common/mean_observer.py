"""Train-mean (centre-of-mass) speed observer of the heavy freight train (seed 002).

Every freight speed controller (:class:`controllers.common.freight_blending.FreightTracker`)
carries one and feeds back ``v_f = (1 - w) v_head + w v_c`` (``mean_weight`` w, per law in the
generated :data:`controllers.common.freight_tuning.TUNING_FILE`; w = 0: the measured head
speed alone).

In the total force balance of the train the coupler forces cancel (eq. 1 summed over the
vehicles, eq. 7): ``M (1 + gamma) dv_c/dt = F_loco - F_air - sum_i F_r,i``, ``v_c`` the
``m_i (1 + gamma_i)``-weighted mean speed. The observer integrates it from what the controller
knows, on the design model of eq. (15)/(18) (:func:`controllers.preview.design.lag_delay_model`,
``z = [v_c, a, held inputs]``):

* ``u`` the locomotive force demand the blending passed on (``force_demand / M (1 + gamma)``),
  through the model's traction lag and dead time;
* ``d = -(F_air + F_r) / M (1 + gamma)`` with the air-brake force of the blending's brake-pipe
  model over the sample (its mean modelled cylinder pressures, friction coefficient at the
  observed speed) and the nominal resistance (eqs. 3-6) at the observed speed and the measured
  head position (grade, curve, tunnel averaged over the train length), the speed terms scaled
  by ``v_c / stiction_speed`` at standstill as the plant does;
* a slow correction toward the measured head speed with an acceleration-bias state ``b``
  (a critically damped second-order observer of bandwidth ``1 / t_c``): at every sample, with
  the innovation ``r = v_head - v_c`` after the prediction, ``v_c += (2 T / t_c) r`` and
  ``b += (T / t_c^2) r``, ``b`` added to the predicted acceleration. The head and the mean
  differ by the train-stretch modes (period about 18 s) and, at the start, by the stretch
  rate, which ``t_c`` much longer than them leaves in the estimate; model error (mass,
  resistance, the air-brake force: a slowly varying acceleration bias) goes into ``b``, so it
  leaves no steady offset (a correction on ``v_c`` alone would leave ``t_c`` times the bias).

Our addition, not the paper's (its design model is one mass, so its measured speed is this one).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from controllers.common.freight_tuning import tuned_param
from cosim.fmu.declare import param
from cosim.fmu.state import StatefulCore
from plants.freight import friction_coefficient_at

if TYPE_CHECKING:
    from controllers.common.freight_blending import FreightBlending
    from controllers.preview.design import DelayedModel


def mean_weight_param(law: str) -> float:
    """The ``mean_weight`` parameter of a freight law, its default the tuned pick."""
    return tuned_param(law, "mean_weight", "1", "weight w of the observed train-mean speed "
                       "in the fed-back speed (1 - w) v_head + w v_mean (0: the head alone)",
                       min=0.0, max=1.0)


def correction_time_param() -> float:
    """The ``observer_correction_time`` parameter (the same for every law)."""
    return param(45.0, "s", "time constant t_c of the mean-speed observer's correction "
                 "toward the head speed (speed and acceleration bias; > 2 sample times)",
                 min=1.0)


def fed_back_speed(v_head: float, v_mean: float, w: float) -> float:
    """``(1 - w) v_head + w v_mean`` (m/s); exactly ``v_head`` for w = 0."""
    return v_head if w == 0.0 else (1.0 - w) * v_head + w * v_mean


class MeanSpeedObserver(StatefulCore):
    """``v_c`` from the force balance of the whole train with a slow head-speed correction
    (speed and acceleration bias)."""

    state_fields = ("z", "bias", "u", "air", "s")

    def __init__(self, model: DelayedModel, blending: FreightBlending, sample_time: float,
                 correction_time: float) -> None:
        if not (sample_time > 0 and correction_time > 0):
            raise ValueError(f"need sample_time > 0 and correction_time > 0 (got "
                             f"{sample_time}, {correction_time})")
        self.model = model
        self.blending = blending
        self.T = float(sample_time)
        self.speed_gain = 2.0 * self.T / correction_time  # critically damped, 1 / t_c
        self.bias_gain = self.T / correction_time**2
        if self.speed_gain >= 1.0:
            raise ValueError(f"correction_time = {correction_time} s must exceed 2 sample "
                             f"times ({2 * self.T} s)")
        self.stiction = float(blending.p.train.stiction_speed)
        self.z: np.ndarray | None = None  # model state [v_c, a, held inputs]; None: not started
        self.bias = 0.0  # m/s^2, estimated acceleration the model misses
        self.u = 0.0  # m/s^2, locomotive demand over the last sample
        self.air = 0.0  # N, mean modelled cylinder pressures of the last sample (force / mu)
        self.s = 0.0  # m, head position at the last sample

    @property
    def speed(self) -> float:
        """Estimated mean speed ``v_c`` (m/s); 0 before the first :meth:`update`."""
        return 0.0 if self.z is None else float(self.z[0])

    def update(self, v_head: float, s_head: float) -> float:
        """Advance over the last sample with its recorded inputs, correct toward the measured
        head speed; returns ``v_c`` (m/s). The first call starts at the head speed."""
        if self.z is None:
            self.z = np.zeros(self.model.n)
            self.z[0] = v_head
            return float(v_head)
        b, m = self.blending, self.model
        vc = float(self.z[0])
        scale = max(min(vc / self.stiction, 1.0), -1.0)  # regularised friction (the plant's)
        s_mid = self.s + 0.5 * self.T * vc
        d = self.bias - (scale * (b.basic_accel(abs(vc)) + self.air * friction_coefficient_at(vc)
                              / b.m_eff) + b.additional_accel(s_mid))
        self.z = m.A @ self.z + m.B[:, 0] * self.u + m.E[:, 0] * d
        r = v_head - float(self.z[0])
        self.z[0] += self.speed_gain * r
        self.bias += self.bias_gain * r
        return float(self.z[0])

    def record(self, force: float, pressures: np.ndarray, s_head: float) -> None:
        """Inputs of the sample just commanded: locomotive force demand (N), the modelled
        cylinder pressures (Pa) over it, the head position (m) at its start."""
        b = self.blending
        self.u = float(force) / b.m_eff
        self.air = float(np.dot(b.model.brake_scale, pressures))
        self.s = float(s_head)

