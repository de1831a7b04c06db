"""Seed 003's tuning picks are today's code's (slow): the picks (written into its scenario
files, no criterion beside them) are the best of their grid when ``papers/seed003/tuning.py``'s
grid is evaluated again. A change to a law, a plant, the route or the master that moves a
criterion makes the picks stale: the failure says which script to run again.

The pick is the grid point of the smallest criterion (as written: rounded to 6 decimals), any
point within floating-point rounding of it (:data:`ROUNDING`, relative) counting as tied, so two
points tied to rounding may swap without failing."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.paper_scripts import paper_script

ROUNDING = 1e-9  # relative: floating-point rounding of a criterion, far above one ulp

pytestmark = pytest.mark.slow

PAPER = Path(__file__).resolve().parents[1]  # papers/seed003


@pytest.mark.parametrize("tracker", ["GPC", "LMI MPC"])
def test_seed003_picks_are_the_best_of_their_grid(built_fmus, tracker: str) -> None:
    import math

    from cosim.run.scenario import load_scenario

    script = paper_script(PAPER / "tuning.py", "seed003_tuning")
    scenario, key, grid, _pattern = script.GRIDS[tracker]
    plants = script.calibration_plants(3)  # the script's default --plants
    picked = float(load_scenario(scenario).components["controller"].parameters[key])
    criteria = {}
    for value in grid:
        mses = [script.evaluate(scenario, key, value, plant) for plant in plants]
        criteria[value] = sum(math.log(m) for m in mses) / len(mses)
    best = min(criteria.values())
    # the grid points at the smallest criterion up to rounding; the script writes the pick
    # rounded to 6 decimals
    tied = {round(v, 6) for v, c in criteria.items() if c <= best + ROUNDING * abs(best)}
    assert picked in tied, (
        f"{tracker}: {key} = {picked} is written, the grid's best is at {sorted(tied)} "
        f"(criterion {best:.6f}): the pick is stale; run `python papers/seed003/tuning.py "
        "--write` again")
