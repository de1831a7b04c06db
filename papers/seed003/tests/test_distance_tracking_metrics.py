"""Seed 003's distance-time tracking (Fig. 6, papers/seed003/metrics.py): the position error up
to the arrival, against closed-form answers on constructed recordings (seed 004's steady-state
speed error is in papers/seed004/tests/test_steady_window_metrics.py)."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

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
