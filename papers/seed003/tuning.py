"""Seed 003: one tuning protocol for the trackers' parameters the paper does not give.

Each tracker's own unprinted parameter is picked the same way: GPC's RLS forgetting factor
(seed 001's value otherwise) and the LMI robust MPC's disturbance-filter gain (ours). The
paper's weights (Q = diag(1, 1, 1), R = 1) stay. Both trackers start from the identified
model (``model_start = "identified"``, the robust MPC's ARX set). The criterion is the mean
over the *calibration* plants of log(speed MSE) on the eco profile (the paper's tracking
comparison, Fig. 5); the calibration plants are mismatch samples drawn from the entry's
``[ensemble] perturb`` with the ``calibration_seeds`` (one draw per seed), never the report
draws. Every tracker gets the same budget, BUDGET points of a log grid.

    python papers/seed003/tuning.py [--plants 3] [--write]

``--write`` puts the picks into the seed 003 scenario files (the lines marked
``# picked by papers/seed003/tuning.py``); without it the table is only printed.
"""

from __future__ import annotations

import argparse
import math
import re
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]  # papers/NAME/ -> the repository
sys.path[:0] = [str(ROOT)]

from cosim.reproduce.entry import load_entry  # noqa: E402
from cosim.run.perturbation import draw_samples, nominal_values, parse_perturb  # noqa: E402

BUDGET = 5  # evaluations per tracker (each on every calibration plant), the same for both
MARK = "# picked by papers/seed003/tuning.py"

# tracker: (eco scenario, parameter, grid, scenario files whose line the pick replaces)
GRIDS = {
    "GPC": ("seed003_crh3_gpc_eco", "forgetting",
            tuple(float(1.0 - x) for x in np.geomspace(0.1, 0.001, BUDGET)),
            "seed003_crh3_gpc_*.toml"),
    "LMI MPC": ("seed003_crh3_lmimpc_eco", "disturbance_gain",
                tuple(float(x) for x in np.geomspace(0.03, 1.0, BUDGET)),
                "seed003_crh3_lmimpc_*.toml"),
}


def calibration_plants(n: int) -> list[dict[str, float]]:
    """One mismatch draw per calibration seed (the first ``n``)."""
    entry = load_entry("seed003")
    perts = parse_perturb(entry.ensemble.perturb)
    nominals = nominal_values(GRIDS["GPC"][0], [p.key for p in perts])
    return [draw_samples(perts, nominals, 1, seed)[0]
            for seed in entry.ensemble.calibration_seeds[:n]]


def evaluate(scenario: str, key: str, value: float, plant: dict[str, float]) -> float:
    from cosim.run.simulate import run_scenario

    summary = run_scenario(scenario, overrides={**plant, f"controller.{key}": value},
                           plot=False).summary
    return float(summary["speed_mse_kmh2"])


def write_pick(pattern: str, key: str, value: float) -> list[Path]:
    """Replace the marked ``key = ...`` line of every matching scenario file."""
    line = re.compile(rf"^{re.escape(key)} = [^#\n]*{re.escape(MARK)}.*$", re.M)
    changed = []
    for path in sorted((ROOT / "papers" / "seed003" / "scenarios").glob(pattern)):
        text = path.read_text()
        new, n = line.subn(f"{key} = {value!r}   {MARK} (mean log speed MSE, "
                           "calibration plants)", text)
        if n != 1:
            raise SystemExit(f"{path}: expected one '{key} = ... {MARK}' line, found {n}")
        path.write_text(new)
        changed.append(path)
    return changed


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--plants", type=int, default=3, help="calibration plants (<= the "
                    "entry's calibration seeds)")
    ap.add_argument("--write", action="store_true", help="write the picks into the scenarios")
    a = ap.parse_args()
    plants = calibration_plants(a.plants)
    print(f"# calibration plants: {plants}")
    for name, (scenario, key, grid, pattern) in GRIDS.items():
        best: tuple[float, float] | None = None
        for value in grid:
            mses = [evaluate(scenario, key, value, p) for p in plants]
            crit = sum(math.log(m) for m in mses) / len(mses)
            print(f"{name:<8} {key:<17} {value:>9.5g}  MSE {' '.join(f'{m:.4g}' for m in mses)}"
                  f"  mean log {crit:.4f}", flush=True)
            if best is None or crit < best[1]:
                best = (value, crit)
        assert best is not None
        print(f"{name:<8} pick: {key} = {best[0]:.6g}")
        if a.write:
            for path in write_pick(pattern, key, round(best[0], 6)):
                print(f"  wrote {path.relative_to(ROOT)}")


if __name__ == "__main__":
    main()
