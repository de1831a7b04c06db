"""Seed 001: one tuning protocol for every law's own gains; writes the picks to
``controllers/datadriven/tuned.py``, the laws' defaults (the FMUs' start values).

Each of the four laws has its own tunable parameters, declared in :data:`GAINS` with a search
box (a decade or more either side of the paper's or the usual value, in log for gains, linear
for fractions and exponents):

* the control law's gains the paper gives for a data scaling it does not state (ISMC's beta,
  the surface's k1, k2, alpha; MFAC's delta and rho) and those it does not give (ISMC's
  boundary layer Delta, eq. 27; ISMPC's move weight theta, eq. 66; GPC's control weight; the
  surface's b, eq. 18);
* our mechanisms' strengths (the force sharing's gain; the truncated inverse's cutoff of the
  three FFDL laws).

Fixed, not tuned, for every law alike: the estimators (the FFDL estimator's mu, lambda and
Phi(1), GPC's RLS forgetting and orders: the paper's, the information every law starts from),
the horizons (ISMPC's N, GPC's Ny and Nu: the paper's), the sample time and data scaling, and
the mechanisms' switches (comfort clip, anti-windup, common sums: the entry's variants).

Every law gets the same protocol and budget (``benchmarks/tuning_protocol.py``: :data:`BUDGET`
evaluations in Sobol stages, each further stage in a box of half the width around the best so
far), after one evaluation of its incumbent (the law's defaults when the script starts: a
search that cannot do better than the setting it starts from keeps it, for every law alike). An
evaluation is the direct core loop (the FMUs run the same cores) on every *calibration* seed
(``[ensemble] calibration_seeds`` of ``papers/seed001/entry.toml``, disjoint from its
report seeds) under both main disturbances (the smooth one, 0.03 m/s2, tau = 10 s, and the
paper's white noise as the scenarios ship it). Criterion (fixed before any ranking was looked
at): the mean of log(MSE x IAE) (eqs. 87, 88, the paper's tracking indices with equal
weight); a diverged run makes the point infinitely bad. Every evaluation goes to
``runs/tuning/seed001.csv``.

    python papers/seed001/tuning.py [--workers 2] [--dry-run] [--from-log]
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import os
import pprint
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np
import tomllib

ROOT = Path(__file__).resolve().parents[2]  # papers/NAME/ -> the repository
sys.path[:0] = [str(ROOT), str(ROOT / "benchmarks")]

from seed001_scaling_sweep import closed_loop  # noqa: E402
from tuning_protocol import (  # noqa: E402
    BUDGET,
    STAGES,
    Gain,
    parameters,
    picks_from_log,
    stage_points,
    write_log,
)

from controllers.datadriven.emu_control import EmuGpc, EmuIsmc, EmuIsmpc, EmuMfac  # noqa: E402
from cosim.papers import paper_metrics  # noqa: E402
from cosim.reproduce.ensemble import parse_seeds  # noqa: E402
from plants.route import load_reference  # noqa: E402

unit_indices = paper_metrics("seed001").unit_indices  # this folder's metrics.py, as registered

ENTRY = ROOT / "papers" / "seed001" / "entry.toml"
OUT = ROOT / "controllers" / "datadriven" / "tuned.py"
LOG_FILE = ROOT / "runs" / "tuning" / "seed001.csv"
DISTURBANCES = (False, True)  # white?: the smooth main rows and the paper's white noise

SHARE = Gain("share_gain", 0.0, 1.0, log=False)
CUTOFF = Gain("pinv_cutoff", 0.0, 1.0, log=False)
SURFACE = (Gain("k1", 0.0, 1.0, log=False), Gain("k2", 0.2, 20.0),
           Gain("alpha", 0.1, 0.99, log=False), Gain("b", 0.001, 0.1))
GAINS: dict[str, tuple[Gain, ...]] = {  # law: its tunable parameters (field names of its core)
    "ISMC": (Gain("boundary_layer", 0.1, 100.0), Gain("beta", 0.005, 0.5), *SURFACE, SHARE,
             CUTOFF),
    "ISMPC": (Gain("theta", 1.0, 1e5), *SURFACE, SHARE, CUTOFF),
    "GPC": (Gain("control_weight", 0.001, 10.0), SHARE),
    "MFAC": (Gain("delta", 0.001, 10.0), Gain("rho", 0.05, 2.0, log=False), SHARE, CUTOFF),
}
CORES = {"ISMC": EmuIsmc, "ISMPC": EmuIsmpc, "GPC": EmuGpc, "MFAC": EmuMfac}


def calibration_seeds() -> list[int]:
    ens = tomllib.loads(ENTRY.read_text())["ensemble"]
    return parse_seeds(f"{ENTRY}: [ensemble]", "calibration_seeds", ens["calibration_seeds"])


def _replace(obj: Any, values: dict[str, Any], found: set[str]) -> Any:
    """``obj`` (a dataclass of parameters, nested) with every field named in ``values`` set."""
    changes = {}
    for f in dataclasses.fields(obj):
        value = getattr(obj, f.name)
        if f.name in values:
            if f.name in found:
                raise KeyError(f"{type(obj).__name__}: {f.name} is declared twice in the law")
            found.add(f.name)
            changes[f.name] = values[f.name]
        elif dataclasses.is_dataclass(value):
            changes[f.name] = _replace(value, values, found)
    return dataclasses.replace(obj, **changes)


def with_values(cls, values: dict[str, Any]):
    """The core's parameters with the law's fields ``values`` (names as :data:`GAINS`)."""
    params = cls.params_class()
    found: set[str] = set()
    law = _replace(params.law, values, found)
    if missing := set(values) - found:
        raise KeyError(f"{cls.__name__}: no law parameter {sorted(missing)}")
    return dataclasses.replace(params, law=law)


def incumbent(law: str) -> dict[str, float]:
    """The law's defaults of its tunable parameters (the values its FMU starts with)."""
    params = CORES[law].params_class().law
    out: dict[str, float] = {}

    def walk(obj: Any) -> None:
        for f in dataclasses.fields(obj):
            value = getattr(obj, f.name)
            if dataclasses.is_dataclass(value):
                walk(value)
            elif f.name in names:
                out[f.name] = value

    names = {g.name for g in GAINS[law]}
    walk(params)
    return {g.name: out[g.name] for g in GAINS[law]}


def run(job: tuple) -> dict:
    name, point, values, white, seed = job
    cls = CORES[name]
    params = with_values(cls, values)
    ctl = cls(params, load_reference("jinan_xuzhou_east_reference"), 3)
    T = params.drive.sample_time
    try:
        v, ref, _ = closed_loop(ctl, white, seed, T)
        m = unit_indices(np.arange(len(ref)) * T, v, ref, 1.0)
        mse, iae = m["unit_mse_kmh2"], m["unit_iae_kmh_s"]
    except (ArithmeticError, ValueError, np.linalg.LinAlgError):
        mse = iae = math.inf
    return dict(name=name, point=point, white=white, seed=seed, mse=mse, iae=iae)


def criterion(rows: list[dict]) -> float:
    """Mean of log(MSE x IAE); a diverged run (non-finite) makes the point infinitely bad."""
    vals = [math.log(r["mse"] * r["iae"]) if r["mse"] > 0 and math.isfinite(r["mse"] * r["iae"])
            else math.inf for r in rows]
    return sum(vals) / len(vals)


def write_picks(picks: dict[str, dict[str, float]], best: dict[str, float],
                seeds: list[int]) -> None:
    protocol = {"budget": BUDGET, "stages": list(STAGES),
                "incumbent": "evaluated first: the law's defaults when the script ran",
                "calibration_seeds": seeds,
                "disturbances": ["smooth (0.03 m/s2, tau = 10 s)", "white (as shipped)"],
                "criterion": "mean of log(MSE x IAE) (eqs. 87, 88; MSE in (km/h)^2, IAE in "
                             "km/h s) over the calibration seeds and both disturbances"}
    boxes = {law: {g.name: [g.lo, g.hi, "log" if g.log else "linear"] for g in gains}
             for law, gains in GAINS.items()}
    edges = {law: [g.name for g in GAINS[law] if g.at_edge(picks[law][g.name])]
             for law in GAINS}
    OUT.write_text(
        '"""Generated by ``python papers/seed001/tuning.py``; do not edit by hand.\n\n'
        "The seed-001 laws' tunable parameters, picked by one protocol (``PROTOCOL``, the\n"
        "search boxes ``BOXES``): the evaluated point with the lowest criterion (``BEST``);\n"
        "``AT_EDGE`` names the picks within 2 % of an end of their box (unit coordinate). The\n"
        'keys are the law cores\' field names (the FMUs\' parameter names).\n"""\n'
        + "".join(f"\n{name} = {pprint.pformat(value, width=90, sort_dicts=False)}\n"
                  for name, value in (("PROTOCOL", protocol), ("BOXES", boxes),
                                      ("TUNED", picks), ("BEST", best),
                                      ("AT_EDGE", edges))))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--dry-run", action="store_true", help=f"do not write {OUT.name}")
    ap.add_argument("--from-log", action="store_true", help=f"pick from the evaluations in "
                    f"{LOG_FILE.relative_to(ROOT)} (a finished run's) instead of running them")
    a = ap.parse_args()
    seeds = calibration_seeds()
    if a.from_log:
        picks, best = picks_from_log(LOG_FILE, GAINS)
        best = {law: round(c, 4) for law, c in best.items()}
        if not a.dry_run:
            write_picks(picks, best, seeds)
            print(f"wrote {OUT.relative_to(ROOT)}")
        return
    runs_per_point = len(DISTURBANCES) * len(seeds)
    print(f"# {len(GAINS)} laws x {BUDGET} evaluations x {runs_per_point} runs (calibration "
          f"seeds {seeds}, smooth and white), load average "
          f"{' '.join(f'{x:.2f}' for x in os.getloadavg())}", flush=True)
    best_u: dict[str, np.ndarray | None] = dict.fromkeys(GAINS)
    best: dict[str, float] = dict.fromkeys(GAINS, math.inf)
    picks: dict[str, dict] = {}
    log: list[dict] = []
    with ProcessPoolExecutor(a.workers) as pool:
        for stage in range(-1, len(STAGES)):
            if stage < 0:  # the incumbents (log stage 0)
                values = {(law, 0): incumbent(law) for law in GAINS}
                points = {law: [np.array([g.unit(values[(law, 0)][g.name])
                                          for g in GAINS[law]])] for law in GAINS}
            else:
                points = {law: stage_points(stage, len(g), best_u[law])
                          for law, g in GAINS.items()}
                values = {(law, i): parameters(GAINS[law], u)
                          for law, us in points.items() for i, u in enumerate(us)}
            jobs = [(law, i, vals, white, seed) for (law, i), vals in values.items()
                    for white in DISTURBANCES for seed in seeds]
            results = list(pool.map(run, jobs, chunksize=4))
            for (law, i), vals in values.items():
                c = criterion([r for r in results if r["name"] == law and r["point"] == i])
                log.append({"law": law, "stage": stage + 1, "point": i, **vals,
                            "criterion": c})
                if c < best[law]:
                    best[law], best_u[law], picks[law] = c, points[law][i], vals
            for law in GAINS:
                print(f"{law:<6} stage {stage + 1}: criterion {best[law]:.4f} at "
                      f"{picks.get(law)}", flush=True)
    failed = [law for law in GAINS if law not in picks]
    if failed:
        raise SystemExit(f"seed001 tuning: every evaluation of {failed} diverged")
    write_log(LOG_FILE, log)
    print(f"wrote {LOG_FILE.relative_to(ROOT)}")
    if not a.dry_run:
        write_picks(picks, {law: round(c, 4) for law, c in best.items()}, seeds)
        print(f"wrote {OUT.relative_to(ROOT)}")


if __name__ == "__main__":
    main()
