"""Metrics of seed 002 (heavy-haul freight speed tracking): the speed errors per driving mode
and the train-mean speed errors, over the moving samples outside the final stop window."""

from __future__ import annotations

from typing import Any

import numpy as np

from cosim.papers import RunRecord, metric
from cosim.run.metrics import KMH_PER_MPS


def _kept(run: RunRecord) -> np.ndarray:
    """The samples the errors are taken over: the reference moving and, with
    ``final_stop_window`` (m) and ``stop_point``, the train before the last metres."""
    keep = run.reference_speed > 0.0
    cfg = run.summary
    if run.position is not None and "final_stop_window" in cfg and "stop_point" in cfg:
        keep &= run.position < float(cfg["stop_point"]) - float(cfg["final_stop_window"])
    return keep


@metric("speed_modes", keys=("reference_accel", "final_stop_window"),
        description="the speed error of the moving samples split by the sign of the reference "
                    "acceleration, the last final_stop_window m before the stop left out",
        outputs={"max_abs_speed_error_traction_kmh": ("max absolute speed error, reference "
                                                      "accelerating", "km/h"),
                 "max_abs_speed_error_cruise_kmh": ("max absolute speed error, reference "
                                                    "constant", "km/h"),
                 "max_abs_speed_error_braking_kmh": ("max absolute speed error, reference "
                                                     "decelerating", "km/h"),
                 "max_abs_speed_error_outside_stop_kmh": ("max absolute speed error over "
                                                          "the kept samples", "km/h"),
                 "speed_rmse_kmh": ("RMS speed error over the kept samples", "km/h")})
def speed_modes(run: RunRecord) -> dict[str, Any]:
    """The samples split by the sign of the ``reference_accel`` column (m/s^2) into traction
    (> 0), cruise (0) and braking (< 0): ``max_abs_speed_error_{traction,cruise,braking}_kmh``;
    with ``final_stop_window`` also ``max_abs_speed_error_outside_stop_kmh``; and
    ``speed_rmse_kmh`` over the same samples."""
    accel = run.series("reference_accel")
    if run.speed is None or run.reference_speed is None or accel is None:
        return {}
    keep = _kept(run)
    err_kmh = (run.speed - run.reference_speed) * KMH_PER_MPS
    out: dict[str, Any] = {}
    if np.any(keep):
        out["speed_rmse_kmh"] = float(np.sqrt(np.mean(err_kmh[keep] ** 2)))
    if "final_stop_window" in run.summary:
        out["max_abs_speed_error_outside_stop_kmh"] = (
            float(np.max(np.abs(err_kmh[keep]))) if np.any(keep) else None)
    for mode, sel in (("traction", accel > 0), ("cruise", accel == 0), ("braking", accel < 0)):
        part = err_kmh[keep & sel]
        out[f"max_abs_speed_error_{mode}_kmh"] = float(np.max(np.abs(part))) if part.size else None
    return out


@metric("train_mean", keys=("vehicle_speeds", "final_stop_window"),
        description="the train-mean speed (plain mean of the vehicle speeds) against the "
                    "reference, over the samples speed_modes keeps",
        outputs={"train_mean_speed_rmse_kmh": ("RMS error of the train-mean speed", "km/h"),
                 "max_abs_train_mean_speed_error_kmh": ("max absolute error of the train-mean "
                                                        "speed", "km/h")})
def train_mean(run: RunRecord) -> dict[str, Any]:
    """The train-mean speed (plain mean of the ``vehicle_speeds`` columns, m/s) against the
    reference: ``train_mean_speed_rmse_kmh`` and ``max_abs_train_mean_speed_error_kmh`` over
    the samples of :func:`speed_modes`."""
    cols = run.columns("vehicle_speeds")
    if not cols or run.speed is None or run.reference_speed is None:
        return {}
    keep = _kept(run)
    if not np.any(keep):
        return {}
    mean = run.frame[cols].to_numpy(dtype=float).mean(axis=1)
    e_mean = (mean - run.reference_speed)[keep] * KMH_PER_MPS
    return {"train_mean_speed_rmse_kmh": float(np.sqrt(np.mean(e_mean**2))),
            "max_abs_train_mean_speed_error_kmh": float(np.max(np.abs(e_mean)))}
