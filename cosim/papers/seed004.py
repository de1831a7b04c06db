"""Seed 004 (Wang et al.) metrics beside the shared ones (:mod:`cosim.run.metrics`).

A controller that tracks the target *speed* but not the timetable *position* can end behind
the train the target describes, and part of its energy saving is then distance not covered.
With the summary keys ``reference_position`` (the recorded timetable position ``s_ref(t)``,
the integral of the target speed, m) and ``position`` (m):

* ``distance_short_m``: ``s_ref - s`` at the end of the run (m; > 0: behind the timetable).
"""

from __future__ import annotations

from typing import Any


def metrics(out: dict[str, Any], cfg: dict[str, Any], frame: Any) -> None:
    """Add the key of the module docstring to ``out`` where the recording has it."""
    ref, pos = cfg.get("reference_position"), cfg.get("position")
    if not (isinstance(ref, str) and isinstance(pos, str)):
        return
    if ref not in frame or pos not in frame or not len(frame):
        return
    out["distance_short_m"] = float(frame[ref].iloc[-1] - frame[pos].iloc[-1])
