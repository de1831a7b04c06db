"""Metrics of seed 001 (EMU speed tracking with multiple power units): the CTCS-3 speed-error
rule (sec. 4.2), the per-unit indices of Table 2 (eqs. 87-89) and the comfort limit as an
evaluated metric.

Units (stated once): the laws read y = v in m/s sampled every 1 s (the reading under which
Table 2's MA, eq. 89, is in m/s2), so the indices are in the units of that reading:

* eq. 87 ``unit_mse_mps2`` = ``1/(nT) sum_i sum_t e_i(t)^2``, (m/s)^2;
* eq. 88 ``unit_iae_m`` = ``1/n sum_i int |e_i| dt`` (trapezoid), m/s x s = m;
* eq. 89 ``unit_ma_mps_per_sample`` (:func:`unit_indices`), m/s per 1-s
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

from typing import Any

import numpy as np

from cosim.papers import RunRecord, metric
from cosim.run.metrics import KMH_PER_MPS, graded_allowance

# CTCS-3 (sec. 4.2): 2 km/h at or below 30 km/h, 2 % of the speed above
CTCS3_LIMIT_KMH = 2.0
CTCS3_BELOW_KMH = 30.0
CTCS3_FRACTION = 0.02


def ctcs3_allowance_kmh(v_ref_kmh: np.ndarray) -> np.ndarray:
    """CTCS-3 speed-error allowance (km/h) at the reference speeds ``v_ref_kmh``."""
    return graded_allowance(v_ref_kmh, CTCS3_LIMIT_KMH, CTCS3_BELOW_KMH, CTCS3_FRACTION)


def ctcs3_speed_error_ok(v_ref_kmh: np.ndarray, error_kmh: np.ndarray) -> bool:
    """CTCS-3 rule: |error| <= 2 km/h at or below 30 km/h, <= 2 % of the speed above."""
    return bool(np.all(np.abs(error_kmh) <= ctcs3_allowance_kmh(v_ref_kmh) + 1e-12))


@metric("ctcs3", description="the CTCS-3 speed-error allowance kept while the reference moves",
        outputs={"ctcs3_speed_error_ok": ("the speed error within the CTCS-3 allowance at "
                                          "every moving sample", "-")})
def ctcs3(run: RunRecord) -> dict[str, Any]:
    """``ctcs3_speed_error_ok``: the speed error keeps the CTCS-3 allowance at every recorded
    sample while the reference is moving (speed tracking only: it means nothing for a stopping
    or freight scenario). Absent when the speed-tracking metrics are undefined."""
    speed, ref = run.speed, run.reference_speed
    if speed is None or ref is None or run.metrics.get("max_abs_speed_error_kmh") is None:
        return {}
    moving = ref > 0.0
    sel = moving if np.any(moving) else slice(None)
    return {"ctcs3_speed_error_ok": ctcs3_speed_error_ok(ref[sel] * KMH_PER_MPS,
                                                        (speed - ref)[sel] * KMH_PER_MPS)}


def unit_indices(t: np.ndarray, speeds: np.ndarray, ref: np.ndarray,
                 ma_sample_time: float) -> dict[str, float]:
    """The indices over the ``n`` power units (``speeds`` (T, n), m/s; ``ref`` (T,)):

    * eq. 87 ``MSE = 1/(nT) sum_i sum_t e_i(t)^2`` over every recorded sample, e in km/h;
    * eq. 88 ``IAE = 1/n sum_i int |e_i| dt`` (trapezoid), km/h s;
    * eq. 89 ``MA = max_{t,i} |y_i(t) - y_i(t-1)|``: the largest speed change of a unit over
      one sample of ``ma_sample_time`` seconds (m/s per sample; speeds interpolated on that
      grid from the start). With a 1 s sample it equals the largest mean acceleration over
      1 s in m/s^2, which is what Table 2 lists; it is not ``max_abs_accel_mps2`` (the largest
      instantaneous train acceleration).
    """
    err_kmh = (speeds - ref[:, None]) * KMH_PER_MPS
    grid = np.arange(t[0], t[-1] + 1e-9, ma_sample_time)
    sampled = np.column_stack([np.interp(grid, t, speeds[:, i]) for i in range(speeds.shape[1])])
    ma = float(np.max(np.abs(np.diff(sampled, axis=0)))) if grid.size > 1 else 0.0
    return {
        "unit_mse_kmh2": float(np.mean(err_kmh**2)),
        "unit_iae_kmh_s": float(np.mean(np.trapezoid(np.abs(err_kmh), t, axis=0))),
        "unit_ma_mps_per_sample": ma,
        "ma_sample_time_s": float(ma_sample_time),
    }


@metric("unit_indices", keys=("unit_speeds", "ma_sample_time"),
        description="Table 2's tracking indices over the power units, errors against the "
                    "reference speed",
        outputs={"unit_mse_kmh2": ("speed MSE over units and samples, eq. 87", "(km/h)^2"),
                 "unit_iae_kmh_s": ("integral of the absolute speed error, mean over the "
                                    "units, eq. 88", "km/h s"),
                 "unit_ma_mps_per_sample": ("largest speed change of a unit over one sample "
                                            "of ma_sample_time, eq. 89", "m/s per sample"),
                 "ma_sample_time_s": ("the sample of eq. 89", "s"),
                 "unit_mse_mps2": ("eq. 87 in SI units", "(m/s)^2"),
                 "unit_iae_m": ("eq. 88 in SI units", "m")})
def unit_indices_metric(run: RunRecord) -> dict[str, Any]:
    """:func:`unit_indices` of the ``unit_speeds`` columns (list or ``"plant.v[*]"``, m/s)
    against the reference speed, at ``ma_sample_time`` (s, default 1.0), and
    :func:`unit_tracking_si` of the same."""
    cols = run.columns("unit_speeds")
    if not cols or run.reference_speed is None or run.time is None:
        return {}
    speeds = run.frame[cols].to_numpy(dtype=float)
    return {**unit_indices(run.time, speeds, run.reference_speed,
                           float(run.summary.get("ma_sample_time", 1.0))),
            **unit_tracking_si(run.time, speeds, run.reference_speed)}


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


@metric("comfort", keys=("unit_accelerations", "comfort_limit"),
        description="the units' accelerations against the comfort limit (default 1 m/s^2)",
        outputs={"unit_max_abs_accel_mps2": ("largest absolute acceleration of any unit",
                                             "m/s^2"),
                 "comfort_exceeded": ("some unit above the limit at some sample", "-"),
                 "comfort_exceedance_s": ("time with some unit above the limit", "s"),
                 "comfort_limit_mps2": ("the limit", "m/s^2")})
def comfort_metric(run: RunRecord) -> dict[str, Any]:
    """:func:`comfort` of the ``unit_accelerations`` columns (list or ``"plant.a[*]"``, m/s2)
    against ``comfort_limit`` (m/s2, default 1)."""
    cols = run.columns("unit_accelerations")
    if not cols or run.time is None:
        return {}
    return comfort(run.time, run.frame[cols].to_numpy(dtype=float),
                   float(run.summary.get("comfort_limit", 1.0)))
