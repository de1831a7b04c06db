"""Metrics of seed 004 (hybrid MPC of the multi-mass CRH3): the distance short of the
timetable and the steady-state speed error of Fig. 9's inset.

A controller that tracks the target *speed* but not the timetable *position* can end behind
the train the target describes, and part of its energy saving is then distance not covered.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from cosim.papers import RunRecord, metric


@metric("distance_short", keys=("reference_position",),
        description="how far the train ends behind its timetable position s_ref(t)",
        outputs={"distance_short_m": ("s_ref - s at the end of the run (> 0: behind the "
                                      "timetable)", "m")})
def distance_short(run: RunRecord) -> dict[str, Any]:
    """With ``reference_position`` (the recorded timetable position s_ref(t), the integral of
    the target speed, m) and the run's position: ``distance_short_m`` = s_ref - s at the end
    of the run (m; > 0: behind the timetable)."""
    ref = run.series("reference_position")
    if ref is None or run.position is None:
        return {}
    return {"distance_short_m": float(ref[-1] - run.position[-1])}


@metric("steady_error", keys=("steady_window",),
        description="the speed error over the steady window [t0, t1] (s) of Fig. 9's inset "
                    "(250-400 s: the cruise between the target's changes at 200 and 600 s)",
        outputs={"speed_rmse_steady_mps": ("RMS of v - v_ref over the samples with "
                                           "t0 <= t <= t1", "m/s"),
                 "max_abs_speed_error_steady_mps": ("largest absolute v - v_ref over those "
                                                    "samples", "m/s")})
def steady_error(run: RunRecord) -> dict[str, Any]:
    """With ``steady_window`` = [t0, t1] (s, the window of Fig. 9's inset, where the paper
    reads the steady-state error) and the run's speed and reference speed:
    ``speed_rmse_steady_mps``, the RMS of v - v_ref over the recorded samples with t0 <= t <=
    t1, and ``max_abs_speed_error_steady_mps``, the largest |v - v_ref| there (m/s). A window
    the recording does not reach gives nothing."""
    window = run.summary.get("steady_window")
    if run.time is None or run.speed is None or run.reference_speed is None:
        return {}
    if not (isinstance(window, (list, tuple)) and len(window) == 2
            and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in window)
            and window[0] < window[1]):
        raise ValueError(f"[summary] steady_window = {window!r}: expected [t0, t1] in s, "
                         "t0 < t1")
    inside = (run.time >= float(window[0])) & (run.time <= float(window[1]))
    if not np.any(inside):
        return {}
    err = run.speed[inside] - run.reference_speed[inside]
    return {"speed_rmse_steady_mps": float(np.sqrt(np.mean(err ** 2))),
            "max_abs_speed_error_steady_mps": float(np.max(np.abs(err)))}
