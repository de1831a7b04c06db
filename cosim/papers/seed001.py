"""Seed 001 (Li, Zhou, Yang 2024, CRH380A EMU): Table 2's indices in SI units and the comfort
limit as an evaluated metric. Pure functions of a run's arrays.

Units (stated once): the laws read y = v in m/s sampled every 1 s (the reading under which
Table 2's MA, eq. 89, is in m/s2), so the indices are in the units of that reading:

* eq. 87 ``unit_mse_mps2`` = ``1/(nT) sum_i sum_t e_i(t)^2``, (m/s)^2;
* eq. 88 ``unit_iae_m`` = ``1/n sum_i int |e_i| dt`` (trapezoid), m/s x s = m;
* eq. 89 ``unit_ma_mps_per_sample`` (:func:`cosim.run.metrics.unit_indices`), m/s per 1-s
  sample = m/s2;

with ``e_i = v_i - v_ref`` over every recorded sample. The paper prints MSE and IAE without a
unit; its km/h figures would be 3.6^2 and 3.6 times these.

Comfort (sec. 4.3: |a| <= 1 m/s2 for the passengers): ``unit_max_abs_accel_mps2`` is the
largest |a_i| of any power unit at any recorded sample, ``comfort_exceeded`` whether it is
above ``limit``, and ``comfort_exceedance_s`` the time during which some unit is above it
(sample-and-hold over the recording). The units' accelerations include the coupler forces
and the disturbance, so a clip of each unit's commanded force per unit mass at the limit
(the controllers' ``accel_max``) does not by itself keep them within it.
"""

from __future__ import annotations

import numpy as np


def unit_tracking_si(t: np.ndarray, speeds: np.ndarray, ref: np.ndarray) -> dict[str, float]:
    """``unit_mse_mps2`` (eq. 87) and ``unit_iae_m`` (eq. 88) of the units' speeds
    ``speeds`` (T, n) in m/s against ``ref`` (T,) in m/s at the times ``t`` (s)."""
    err = np.asarray(speeds, float) - np.asarray(ref, float)[:, None]
    return {"unit_mse_mps2": float(np.mean(err ** 2)),
            "unit_iae_m": float(np.mean(np.trapezoid(np.abs(err), np.asarray(t, float),
                                                     axis=0)))}


def comfort(t: np.ndarray, accels: np.ndarray, limit: float) -> dict[str, float | bool]:
    """The comfort metrics of the units' accelerations ``accels`` (T, n), m/s2, against
    ``limit`` (m/s2), at the times ``t`` (s)."""
    a = np.abs(np.asarray(accels, float))
    t = np.asarray(t, float)
    peak = float(a.max()) if a.size else 0.0
    over = a.max(axis=1) > limit if a.size else np.zeros(0, bool)
    held = np.diff(t) if t.size > 1 else np.zeros(0)
    return {"unit_max_abs_accel_mps2": peak, "comfort_exceeded": bool(peak > limit),
            "comfort_exceedance_s": float(np.sum(held[over[:-1]])) if held.size else 0.0,
            "comfort_limit_mps2": float(limit)}
