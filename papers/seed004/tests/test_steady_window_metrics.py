"""Seed 004's steady-state speed error over Fig. 9's inset window (papers/seed004/metrics.py),
against closed-form answers on constructed recordings."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from cosim import papers


def _steady(window: object, t: np.ndarray, err: np.ndarray) -> dict:
    ref = np.full_like(t, 30.0)
    frame = pd.DataFrame({"time": t})
    run = papers.RunRecord(frame=frame, summary={"steady_window": window}, time=t,
                           speed=ref + err, reference_speed=ref)
    return papers.compute(["steady_error"], run)


def test_steady_error_is_the_speed_error_inside_the_window_only() -> None:
    t = np.arange(0.0, 601.0)
    err = np.where((t >= 250.0) & (t <= 400.0), 0.3, 5.0)  # 0.3 m/s inside, 5 outside
    err[300] = -0.7
    out = _steady([250.0, 400.0], t, err)
    inside = err[250:401]
    assert inside.size == 151
    # the metric sees (30 + e) - 30: each error off by at most one ulp of 30 m/s, and so
    # the RMS and the largest error (a bound from the numerics, the same on any CPU)
    ulp = float(np.spacing(30.0))
    assert out["speed_rmse_steady_mps"] == pytest.approx(math.sqrt(np.mean(inside ** 2)),
                                                         rel=0.0, abs=ulp)
    assert out["max_abs_speed_error_steady_mps"] == pytest.approx(0.7, rel=0.0, abs=ulp)
    assert _steady([700.0, 800.0], t, err) == {}  # a window the recording never reaches


@pytest.mark.parametrize("window", [None, [400.0, 250.0], [250.0], "250-400", [True, 400.0]])
def test_a_bad_steady_window_names_the_key_and_value(window: object) -> None:
    t = np.arange(0.0, 10.0)
    with pytest.raises(ValueError, match=r"\[summary\] steady_window = "):
        _steady(window, t, np.zeros_like(t))
