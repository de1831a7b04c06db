"""Run-dependent diagnostics of an FMU (solver wall and CPU times): kept out of the FMU state
and of the outputs, which must be deterministic, bounded in memory, and reported
once, through the FMI log at fmi2Terminate (bundled into every FMU; stdlib only).

The log message is ``"<instance>: diagnostics {json}"`` (:data:`TAG`), read by the master into
``RunResult.diagnostics`` and by :mod:`cosim.run.metrics` into ``summary.json``
(``qp_solve_time_median_s``, ``qp_solve_time_total_s``, ``qp_cpu_time_total_s``,
``qp_cpu_time_median_s``); any other
host shows it in its FMU log.
"""

from __future__ import annotations

import json
import math
import statistics
from collections import deque
from typing import Any

TAG = "diagnostics "
WINDOW = 1001  # solve times over which the median is taken (the latest ones)


class SolveTimes:
    """Per-event solve times: median over the latest :data:`WINDOW`, wall and CPU totals.

    Not part of any core state (a restored FMU keeps counting the time it really spent);
    memory does not grow with the run length.
    """

    def __init__(self, window: int = WINDOW) -> None:
        self.recent: deque[float] = deque(maxlen=window)
        self.recent_cpu: deque[float] = deque(maxlen=window)
        self.total = 0.0
        self.cpu_total = 0.0
        self.events = 0

    def add(self, wall_s: float, cpu_s: float = 0.0) -> None:
        self.recent.append(wall_s)
        self.recent_cpu.append(cpu_s)
        self.total += wall_s
        self.cpu_total += cpu_s
        self.events += 1

    def diagnostics(self) -> dict[str, float]:
        """The figures reported at termination (s); the median counts positive times only
        (an event that did not solve anything reports 0)."""
        solved = [x for x in self.recent if x > 0.0]
        out = {"qp_solve_time_median": statistics.median(solved) if solved else 0.0,
               "qp_solve_time_total": self.total, "qp_solve_events": self.events}
        if self.cpu_total:
            out["qp_cpu_time_total"] = self.cpu_total
            cpu = [x for x in self.recent_cpu if x > 0.0]
            out["qp_cpu_time_median"] = statistics.median(cpu) if cpu else 0.0
        return out


def message(instance: str, figures: dict[str, Any]) -> str:
    """The log line carrying ``figures`` (finite numbers only)."""
    clean = {k: v for k, v in figures.items()
             if isinstance(v, (int, float)) and math.isfinite(v)}
    return f"{instance}: {TAG}{json.dumps(clean, sort_keys=True)}"


def parse(messages: list[str]) -> dict[str, float]:
    """The figures of the last diagnostics line among an FMU's log ``messages`` ({} if none)."""
    for text in reversed(messages):
        head, sep, body = text.partition(f": {TAG}")
        if sep and body.startswith("{"):
            try:
                figures = json.loads(body)
            except ValueError:
                continue
            if isinstance(figures, dict):
                return {k: v for k, v in figures.items() if isinstance(v, (int, float))}
    return {}
