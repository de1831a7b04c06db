"""Seed 002 summary metrics (papers/seed002/metrics.py): per-mode speed errors and train-mean
errors; the command range and variation of the generic summary."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from cosim import papers
from cosim.run.metrics import command_range


def test_mode_errors_window_command_variation_and_train_mean() -> None:
    s = np.array([0.0, 100.0, 200.0, 300.0, 400.0, 470.0])
    ref = np.array([1.0, 2.0, 2.0, 1.5, 1.0, 0.5])
    v = ref + np.array([0.1, -0.2, 0.05, 0.3, -0.1, 2.0]) / 3.6
    frame = pd.DataFrame({
        "s": s, "v": v, "ref": ref, "a": [0.1, 0.1, 0.0, -0.1, -0.1, -0.1],
        "u": [0.0, 0.5, -0.5, 0.5, 0.0, 0.0],
        "v[1]": v, "v[2]": v + 0.2 / 3.6,
    })
    cfg = {"reference_accel": "a", "final_stop_window": 50.0, "stop_point": 500.0,
           "accel_command": "u", "vehicle_speeds": "v[*]"}
    run = papers.RunRecord(frame=frame, summary=cfg, position=s, speed=v, reference_speed=ref)
    out = {**papers.compute(["speed_modes", "train_mean"], run), **command_range(frame["u"])}
    assert out["max_abs_speed_error_traction_kmh"] == pytest.approx(0.2)
    assert out["max_abs_speed_error_cruise_kmh"] == pytest.approx(0.05)
    assert out["max_abs_speed_error_braking_kmh"] == pytest.approx(0.3)  # 470 m left out
    assert out["max_abs_speed_error_outside_stop_kmh"] == pytest.approx(0.3)
    assert out["command_min"] == -0.5 and out["command_max"] == 0.5
    assert out["command_total_variation"] == pytest.approx(3.0)
    kept = np.array([0.1, -0.2, 0.05, 0.3, -0.1])  # moving, not in the last 50 m
    assert out["speed_rmse_kmh"] == pytest.approx(np.sqrt(np.mean(kept**2)))
    # train mean = head + 0.1 km/h: errors 0.2, -0.1, 0.15, 0.4, 0.0 over the kept samples
    assert out["max_abs_train_mean_speed_error_kmh"] == pytest.approx(0.4)
    assert out["train_mean_speed_rmse_kmh"] == pytest.approx(
        np.sqrt(np.mean(np.array([0.2, -0.1, 0.15, 0.4, 0.0]) ** 2)))
