"""The tuning protocol every tuned law of a reproduction gets (seeds 001 and 002): a search box
per tunable parameter and the same budget of evaluations, spent in Sobol stages.

* stage 1: :data:`STAGES` [0] points of a scrambled Sobol sequence (``scipy.stats.qmc``, the same
  seed for every law) in the law's box;
* each further stage: the next number of Sobol points in a box of half the previous width (in
  the box's unit coordinates) around the best point so far, moved to stay inside the box.

The scripts that use it (``papers/seed001/tuning.py``, ``papers/seed002/tuning.py``) declare the
boxes, the criterion and the calibration seeds. It stays in ``benchmarks/`` as a library the two
papers share (they put ``benchmarks/`` on ``sys.path``); it belongs to no one paper.
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.stats import qmc

STAGES = (32, 16, 16)  # Sobol points per stage (powers of two: balanced); the same for every law
BUDGET = sum(STAGES)  # evaluations per law, each on every calibration seed
SOBOL_SEED = 2      # the scrambling of stage k uses SOBOL_SEED + k, for every law
EDGE = 0.02  # a pick this close to an end of its box (unit coordinate) is flagged


@dataclass(frozen=True)
class Gain:
    """A tunable parameter of a law: its FMU name, its search range and scale."""

    name: str
    lo: float
    hi: float
    log: bool = True
    integer: bool = False
    also: tuple[str, ...] = ()  # parameters given the same value (the preview's M_d = M_R)

    def value(self, u: float) -> float | int:
        """The value at unit coordinate ``u`` in [0, 1] (6 significant digits)."""
        x = self.lo * (self.hi / self.lo) ** u if self.log else self.lo + (self.hi - self.lo) * u
        return int(round(x)) if self.integer else float(f"{x:.6g}")

    def unit(self, value: float) -> float:
        """The unit coordinate of ``value`` (the inverse of :meth:`value`)."""
        if self.log:
            return math.log(value / self.lo) / math.log(self.hi / self.lo)
        return (value - self.lo) / (self.hi - self.lo)

    def at_edge(self, value: float) -> bool:
        """Whether ``value`` lies within :data:`EDGE` of an end of the box (unit coordinate):
        the best point may lie outside it."""
        return not EDGE <= self.unit(value) <= 1.0 - EDGE


def parameters(gains: tuple[Gain, ...], u: np.ndarray) -> dict[str, float | int]:
    """The parameter values at the point ``u`` of the unit cube."""
    out: dict[str, float | int] = {}
    for g, x in zip(gains, u, strict=True):
        out[g.name] = g.value(float(x))
        out.update({name: out[g.name] for name in g.also})
    return out


def stage_points(stage: int, dims: int, best: np.ndarray | None) -> np.ndarray:
    """The unit-cube points of ``stage`` (0-based): Sobol points in the whole cube, then in a
    box of width 2**-stage around ``best``, moved to lie inside the cube."""
    points = qmc.Sobol(dims, scramble=True, seed=SOBOL_SEED + stage).random(STAGES[stage])
    if stage == 0:
        return points
    width = 0.5 ** stage
    low = np.clip(best - width / 2, 0.0, 1.0 - width)
    return low + width * points


def write_log(path: Path, rows: list[dict]) -> None:
    """Every evaluation (one row each: law, stage, point, its values, criterion) as CSV."""
    path.parent.mkdir(parents=True, exist_ok=True)
    keys = list(dict.fromkeys(k for row in rows for k in row))
    with path.open("w", newline="") as f:
        writer = csv.DictWriter(f, keys)
        writer.writeheader()
        writer.writerows(rows)


def picks_from_log(path: Path, gains: dict[str, tuple[Gain, ...]]
                   ) -> tuple[dict[str, dict], dict[str, float]]:
    """Each law's best evaluation in the log ``path`` (:func:`write_log`; the first of equal
    ones, as a run picks) and its criterion."""
    picks: dict[str, dict] = {}
    best: dict[str, float] = {}
    with path.open(newline="") as f:
        for row in csv.DictReader(f):
            law, c = row["law"], float(row["criterion"])
            if law in gains and c < best.get(law, math.inf):
                names = [n for g in gains[law] for n in (g.name, *g.also)]
                integer = {n for g in gains[law] if g.integer for n in (g.name, *g.also)}
                best[law] = c
                picks[law] = {n: int(row[n]) if n in integer else float(row[n]) for n in names}
    missing = [law for law in gains if law not in picks]
    if missing:
        raise SystemExit(f"{path}: no finished evaluation of {missing}")
    return picks, best
