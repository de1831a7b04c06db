"""Metrics of seed 004 (hybrid MPC of the multi-mass CRH3).

A controller that tracks the target *speed* but not the timetable *position* can end behind
the train the target describes, and part of its energy saving is then distance not covered.
"""

from __future__ import annotations

from typing import Any

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
