"""A sweep's grid: ``--set KEY=VALUES`` items parsed, their points counted against a limit
before any is listed, and the points in order."""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterable, Sequence
from typing import Any

from cosim.run import MAX_RUNS
from cosim.run.scenario import parse_value

__all__ = ["MAX_RUNS", "check_runs", "grid_points", "parse_grid"]


def parse_grid(items: Iterable[str]) -> dict[str, Sequence[Any]]:
    """``["controller.N=3..15", "controller.beta=1,2"]`` -> ``{"controller.N": range(3, 16),
    "controller.beta": [1, 2]}`` (an integer range stays a ``range``: it is counted by
    :func:`check_runs` before any list of it is made)."""
    grid: dict[str, Sequence[Any]] = {}
    for item in items:
        key, sep, text = item.partition("=")
        if not sep or not key.strip() or not text.strip():
            raise ValueError(f"--set {item!r}: expected KEY=VALUES, e.g. controller.N=3..15")
        text = text.strip()
        if ".." in text:
            lo, _, hi = text.partition("..")
            try:
                first, last = int(lo), int(hi)
            except ValueError as err:
                raise ValueError(f"--set {item!r}: a range needs integers, e.g. 3..15") from err
            if last < first:
                raise ValueError(f"--set {item!r}: empty range {first}..{last}")
            grid[key.strip()] = range(first, last + 1)  # its size checked before a list
        else:
            grid[key.strip()] = [parse_value(v.strip()) for v in text.split(",")]
    return grid


def check_runs(grid: dict[str, Sequence[Any]], scenarios: int, max_runs: int,
               samples: int = 1) -> None:
    """ValueError naming the count and ``--max-runs`` when the grid's points times
    ``scenarios`` (times ``samples`` per point) exceed ``max_runs``; counted, not listed."""
    points = math.prod(len(values) for values in grid.values())
    runs = points * scenarios * samples
    if runs > max_runs:
        per = f" x {samples} samples" if samples > 1 else ""
        raise ValueError(f"the sweep has {runs:,} runs ({points:,} grid points x {scenarios} "
                         f"scenario(s){per}), more than --max-runs {max_runs:,}: give "
                         f"--max-runs {runs} to run them all")


def grid_points(grid: dict[str, Sequence[Any]]) -> list[dict[str, Any]]:
    """Cartesian product of the grid, in order (first key slowest)."""
    keys = list(grid)
    return [dict(zip(keys, values, strict=True))
            for values in itertools.product(*(list(grid[k]) for k in keys))]
