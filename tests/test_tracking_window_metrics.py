"""Paper metrics of tracking over a part of the run: seed 003's distance-time tracking (Fig. 6)
up to the arrival and seed 004's steady-state speed error over Fig. 9's inset window, against
closed-form answers on constructed recordings."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from cosim import papers
from cosim.run.metrics import _arrival_index


def test_distance_tracking_is_the_position_error_up_to_the_arrival() -> None:
    # a position error of 2 m from 0 to 4 s, -1 m at 5-6 s; at rest from 7 s, when the
    # time-indexed reference runs away (30 m): those samples are not counted
    t = np.arange(10.0)
    v = np.array([1, 1, 1, 1, 1, 1, 1, 0, 0, 0], dtype=float)
    err = np.array([2, 2, 2, 2, 2, -1, -1, 30, 30, 30], dtype=float)
    s = np.cumsum(v)
    frame = pd.DataFrame({"time": t, "p.s": s, "p.v": v, "c.s_ref": s - err})
    arrival = _arrival_index(v)
    assert arrival == 7
    run = papers.RunRecord(frame=frame, summary={"reference_position": "c.s_ref"},
                           position=s, speed=v, arrival_index=arrival)
    out = papers.compute(["distance_tracking"], run)
    expected = np.concatenate([err[:7], [30.0]])  # up to and including the arrival sample
    # whole metres: s - s_ref is exact, so the metric sums the same values in the same order
    assert out["distance_rmse_m"] == math.sqrt(np.mean(expected ** 2))
    assert out["max_abs_distance_error_m"] == 30.0
    still = papers.RunRecord(frame=frame, summary={"reference_position": "c.s_ref"},
                             position=s, speed=v, arrival_index=None)  # never at rest
    assert papers.compute(["distance_tracking"], still)["distance_rmse_m"] == math.sqrt(
        np.mean(err ** 2))
    assert papers.compute(["distance_tracking"], papers.RunRecord(
        frame=frame, summary={}, position=s)) == {}


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
