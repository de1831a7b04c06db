"""Exact dead time for sampled inputs, and the sub-step grid every plant integrates on.

A plant keeps a command history ``[[tick, value], ...]`` (a plain list, so it is part of the
FMU state): the value acts at the plant input from its tick on, and at the lagged element
``delay`` later. Because commands keep their time stamps, the dead time is exact for any
communication step (no shift register tied to one step size).
"""

from __future__ import annotations

from collections.abc import Iterable

BEFORE_START = -(2**62)  # tick of the command held before the run starts


def new_history(initial: float) -> list[list[float]]:
    """A history holding ``initial`` since before the start."""
    return [[BEFORE_START, float(initial)]]


def record(history: list[list[float]], tick: int, value: float) -> None:
    """Append ``value`` acting from ``tick`` if it differs from the last one."""
    if value != history[-1][1]:
        history.append([tick, float(value)])


def delayed(history: list[list[float]], tick: int, delay_ticks: int) -> float:
    """The command ``delay_ticks`` before ``tick``: u(t - Td)."""
    target = tick - delay_ticks
    value = history[0][1]
    for start, u in history:
        if start > target:
            break
        value = u
    return value


def prune(history: list[list[float]], tick: int, delay_ticks: int) -> None:
    """Drop commands that can no longer act after ``tick`` (keep the one acting then)."""
    target = tick - delay_ticks
    while len(history) > 1 and history[1][0] <= target:
        history.pop(0)


def substep_ends(t_ticks: int, h_ticks: int, grids: Iterable[int],
                 history: list[list[float]] | None = None, delay_ticks: int = 0) -> list[int]:
    """Sorted ends of the sub-steps over ``[t, t + h]``: every absolute multiple of each grid
    (e.g. ``max_step``), every instant a delayed command starts to act, and ``t + h``."""
    end = t_ticks + h_ticks
    cuts = {end}
    for grid in grids:
        if grid > 0:
            cuts.update(range((t_ticks // grid + 1) * grid, end, grid))
    if history is not None:
        cuts.update(int(start) + delay_ticks for start, _ in history
                    if t_ticks < int(start) + delay_ticks < end)
    return sorted(cuts)
