"""Seed 002: one tuning protocol for every freight law's own gains; writes the picks.

Each law as the reproduction runs it (a row of ``scenarios/reproduce/seed002.toml``: the
optimal preview, the paper's sliding mode, the sliding mode with a boundary layer, the paper's
fuzzy PID, the fuzzy PID with the PID's feedforward, the PID) has its own tunable parameters,
declared in :data:`GAINS` with a search box (a decade or more either side of the usual value, in
log for gains, linear for the observer weight w and the feedforward look-ahead). Every law gets
the same protocol and the same budget, :data:`BUDGET` evaluations:

* stage 1: :data:`STAGES` [0] points of a scrambled Sobol sequence (``scipy.stats.qmc``, the same
  seed for every law) in the law's box;
* each further stage: the next number of Sobol points in a box of half the previous width (in
  the box's unit coordinates) around the best point so far, moved to stay inside the box.

An evaluation is the full scenario run of ``cosim reproduce`` (the FMUs on the entry's build,
the plant's compiled kernel, the entry's row with its disturbance) on every calibration
disturbance seed (``plant.disturbance_seed``: the entry's ``calibration_seeds``, disjoint from
its report seeds, which loading the entry checks). Criterion (fixed before any ranking was
looked at): the mean over those seeds of ``log(RMSE_mean x RMSE_head)``, the train-mean RMSE
(the speed of the paper's one-mass design model, eq. 18) and the head RMSE (the measured speed,
whose stretch modes the feedback must keep damped) with equal weight; a failed run counts as
infinitely bad. Fixed, not tuned, for every law alike: the sample time, the blending, the
observer's correction time; the preview's q_e = 1 (only H / q_e matters) and q_dz = 0; the PID's
kd = 0 (a PI, as freight speed loops are) and its demand and jerk limits; the fuzzy rule bases.

The picks go to ``controllers/common/freight_tuning.toml``: the four laws' FMUs take their
tables as their parameters' defaults, the two other rows name theirs (``[[runs]] tuned``);
nothing is typed by hand. Every evaluation goes to ``runs/tuning/seed002.csv``.

    python benchmarks/seed002_tuning.py [--workers 2] [--build native|python] [--dry-run]
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import os
import re
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.stats import qmc

ROOT = Path(__file__).resolve().parent.parent
sys.path[:0] = [str(ROOT)]

from controllers.common.freight_tuning import TUNING_FILE  # noqa: E402

STAGES = (32, 16, 16)  # Sobol points per stage (powers of two: balanced); the same for every law
BUDGET = sum(STAGES)  # evaluations per law, each on every calibration seed
SOBOL_SEED = 2      # the scrambling of stage k uses SOBOL_SEED + k, for every law
SEED_KEY = "plant.disturbance_seed"
METRICS = ("train_mean_speed_rmse_kmh", "speed_rmse_kmh")
FMU = "controller"  # the component every freight scenario names its law
LOG_FILE = ROOT / "runs" / "tuning" / "seed002.csv"
EDGE = 0.02  # a pick this close to an end of its box (unit coordinate) is flagged in the file
# the laws whose candidates run on the controller's Python FMU: the native preview carries the
# gains of its declared design only (computed when it is built, from the picks), and equals the
# Python FMU to rounding (tests/test_native_freight_controllers.py)
PYTHON_CONTROLLER = {"Preview"}


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


W = Gain("mean_weight", 0.0, 1.0, log=False)  # the observer weight: every law has it
PI = (Gain("kp", 0.03, 3.0), Gain("ki", 0.001, 0.1))
FUZZY = (*PI, Gain("kp_scale", 0.005, 0.5), Gain("ki_scale", 0.0003, 0.03),
         Gain("e_scale", 0.014, 1.4), Gain("ec_scale", 0.002, 0.2))
SMC = (Gain("lambda", 0.005, 0.5), Gain("q", 0.03, 3.0), Gain("eps", 0.003, 0.3))
LOOK_AHEAD = Gain("preview_time", 0.0, 6.0, log=False)
GAINS: dict[str, tuple[Gain, ...]] = {  # row of the entry (a table of the file): its gains
    "Preview": (Gain("h", 1e2, 1e6), Gain("M_R", 25, 400, integer=True, also=("M_d",)), W),
    "SMC": (*SMC, W),
    "SMC, boundary layer": (*SMC, Gain("boundary_layer", 0.01, 1.0), W),
    "FPID": (*FUZZY, W),
    "FPID + feedforward": (*FUZZY, LOOK_AHEAD, W),
    "PID": (*PI, LOOK_AHEAD, W),
}


def criterion(summaries: list[dict | None]) -> float:
    """Mean over the seeds of log(train-mean RMSE x head RMSE); inf if a run failed."""
    if any(s is None for s in summaries):
        return math.inf
    return float(np.mean([math.log(s[METRICS[0]] * s[METRICS[1]]) for s in summaries]))


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


def write_picks(picks: dict[str, dict], best: dict[str, float], seeds: list[int],
                path: Path = TUNING_FILE) -> None:
    """The tuning file: one table per law, its picks and how they were found."""
    lines = ["# Generated by benchmarks/seed002_tuning.py: do not edit.",
             f"# Protocol: each law's gains (search boxes in the script's GAINS), {BUDGET} "
             f"evaluations per law: Sobol stages of {list(STAGES)} points,",
             "# each further stage in a box of half the width around the best so far; "
             f"calibration seeds {SEED_KEY} = {seeds};",
             "# criterion: mean over the seeds of log(train-mean RMSE x head RMSE) (km/h), the "
             "smallest wins.", ""]
    for law, values in picks.items():
        header = law if re.fullmatch(r"[A-Za-z0-9_-]+", law) else json.dumps(law)
        edges = [f"{g.name} ({g.value(0.0 if g.unit(values[g.name]) < 0.5 else 1.0):g})"
                 for g in GAINS[law] if g.at_edge(values[g.name])]
        lines += [f"[{header}]", f"# criterion {best[law]:.4f}"]
        if edges:
            lines.append(f"# at an end of its search box: {', '.join(edges)}")
        lines += [f"{key} = {value!r}" for key, value in values.items()]
        lines.append("")
    path.write_text("\n".join(lines))


def picks_from_log(path: Path) -> tuple[dict[str, dict], dict[str, float]]:
    """Each law's best evaluation in the log ``path`` (the first of equal ones, as a run picks)
    and its criterion."""
    picks: dict[str, dict] = {}
    best: dict[str, float] = {}
    with path.open(newline="") as f:
        for row in csv.DictReader(f):
            law, c = row["law"], float(row["criterion"])
            if law in GAINS and c < best.get(law, math.inf):
                names = [n for g in GAINS[law] for n in (g.name, *g.also)]
                integer = {n for g in GAINS[law] if g.integer for n in (g.name, *g.also)}
                best[law] = c
                picks[law] = {n: int(row[n]) if n in integer else float(row[n]) for n in names}
    missing = [law for law in GAINS if law not in picks]
    if missing:
        raise SystemExit(f"{path}: no finished evaluation of {missing}")
    return picks, best


def main() -> None:
    from cosim.reproduce.builds import build_overrides
    from cosim.reproduce.entry import load_entry
    from cosim.run.ensemble import execute
    from cosim.run.scenario import load_scenario
    from cosim.run.simulate import ensure_built

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--build", choices=("native", "python"), default=None,
                    help="the FMU builds (default: the entry's)")
    ap.add_argument("--dry-run", action="store_true", help="print the picks, write nothing")
    ap.add_argument("--from-log", action="store_true", help=f"pick from the evaluations in "
                    f"{LOG_FILE.relative_to(ROOT)} (a finished run's) instead of running them")
    a = ap.parse_args()
    if a.from_log:
        picks, best = picks_from_log(LOG_FILE)
        if not a.dry_run:
            write_picks(picks, best, list(load_entry("seed002").ensemble.calibration_seeds))
            print(f"wrote {TUNING_FILE}")
        return
    entry = load_entry("seed002")
    seeds = list(entry.ensemble.calibration_seeds)
    rows = {r.name: r for r in entry.runs}
    base = {}
    for law in GAINS:
        run = rows[law]
        own = {**run.overrides, **({f"{FMU}.build": "python"} if law in PYTHON_CONTROLLER
                                   else {})}
        base[law] = {**own, **build_overrides(run.scenario, own, a.build or entry.build)}
        ensure_built(load_scenario(run.scenario, base[law]))
    print(f"# {len(GAINS)} laws x {BUDGET} evaluations x {len(seeds)} seeds, load average "
          f"{' '.join(f'{x:.2f}' for x in os.getloadavg())}", file=sys.stderr)
    best_u: dict[str, np.ndarray | None] = dict.fromkeys(GAINS)
    best: dict[str, float] = dict.fromkeys(GAINS, math.inf)
    picks: dict[str, dict] = {}
    log: list[dict] = []
    for stage in range(len(STAGES)):
        points = {law: stage_points(stage, len(g), best_u[law]) for law, g in GAINS.items()}
        jobs = [((law, f"{stage}.{i}", seed, 0), rows[law].scenario,
                 {**base[law], **{f"{FMU}.{k}": v for k, v in parameters(GAINS[law], u).items()},
                  SEED_KEY: seed})
                for law, us in points.items() for i, u in enumerate(us) for seed in seeds]
        out = execute(jobs, a.workers, f"seed002 tuning, stage {stage + 1} of {len(STAGES)}",
                      reference_path=False)
        for law, us in points.items():
            for i, u in enumerate(us):
                runs = [out[(law, f"{stage}.{i}", s, 0)] for s in seeds]
                c = criterion(runs)
                values = parameters(GAINS[law], u)
                log.append({"law": law, "stage": stage + 1, "point": i, **values,
                            "criterion": c})
                if c < best[law]:
                    best[law], best_u[law], picks[law] = c, u, values
            print(f"{law:<20} stage {stage + 1}: criterion {best[law]:.4f} at {picks[law]}")
    failed = [law for law in GAINS if law not in picks]
    if failed:
        raise SystemExit(f"seed002 tuning: every evaluation of {failed} failed (see above)")
    LOG_FILE.parent.mkdir(parents=True, exist_ok=True)
    keys = list(dict.fromkeys(k for row in log for k in row))
    with LOG_FILE.open("w", newline="") as f:
        writer = csv.DictWriter(f, keys)
        writer.writeheader()
        writer.writerows(log)
    print(f"wrote {LOG_FILE}")
    if not a.dry_run:
        write_picks(picks, best, seeds)
        print(f"wrote {TUNING_FILE}")


if __name__ == "__main__":
    main()
