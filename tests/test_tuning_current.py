"""The generated tuning picks are today's code's (slow): each law's picked parameters, evaluated
again by its tuning script's own criterion on the calibration seeds, give the criterion the
script recorded beside them (seed 001: ``BEST`` in ``controllers/datadriven/tuned.py``, the core
closed loops of ``papers/seed001/tuning.py``; seed 002: the ``# criterion`` line of each
table of ``controllers/common/freight_tuning.toml``, the FMU runs of
``papers/seed002/tuning.py``); seed 003's picks (written into its scenario files, no
criterion beside them) are the best of their grid when ``papers/seed003/tuning.py``'s
grid is evaluated again. A change to a law, a plant, the route or the master that moves a
criterion makes the picks stale: the failure says which script to run again.

Tolerance: half a unit of the recorded criterion's 4th decimal (it is printed ``%.4f``); the
evaluation is the same deterministic computation as the script's, so on any machine it differs
from the recorded value only by that rounding (and floating-point rounding far below it).
Seed 003: the pick is the grid point of the smallest criterion (as written: rounded to 6
decimals), any point within floating-point rounding of it (:data:`ROUNDING`, relative) counting
as tied, so two points tied to rounding may swap without failing."""

from __future__ import annotations

import importlib.util
import re
import sys
from pathlib import Path
from types import ModuleType

import pytest

from controllers.common.freight_tuning import TUNING_FILE
from controllers.datadriven import tuned

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib  # type: ignore[no-redef]

ROOT = Path(__file__).resolve().parents[1]
PRINTED = 0.5e-4  # half a unit of the 4th decimal of the recorded criterion
ROUNDING = 1e-9  # relative: floating-point rounding of a criterion, far above one ulp

pytestmark = pytest.mark.slow


def _script(name: str) -> ModuleType:
    if name in sys.modules:
        return sys.modules[name]
    paper = name.removesuffix("_tuning")  # seed001_tuning: papers/seed001/tuning.py
    spec = importlib.util.spec_from_file_location(name, ROOT / "papers" / paper / "tuning.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)  # type: ignore[union-attr]
    return module


@pytest.mark.parametrize("law", sorted(tuned.TUNED))
def test_seed001_picks_give_their_recorded_criterion(law: str) -> None:
    script = _script("seed001_tuning")
    rows = [script.run((law, 0, tuned.TUNED[law], white, seed))
            for white in script.DISTURBANCES for seed in script.calibration_seeds()]
    c = script.criterion(rows)
    assert abs(c - tuned.BEST[law]) <= PRINTED, (
        f"{law}: its picks give criterion {c:.6f}, the tuning recorded {tuned.BEST[law]}: the "
        "picks are stale; run `python papers/seed001/tuning.py` again")


def _seed002_best() -> dict[str, float]:
    """The criterion recorded above each table's values."""
    best, law = {}, None
    for line in TUNING_FILE.read_text().splitlines():
        header = re.fullmatch(r"\[(.+)\]", line)
        if header:
            law = header.group(1).strip('"')
        found = re.fullmatch(r"# criterion (-?[0-9.]+|inf)", line)
        if found and law is not None:
            best[law] = float(found.group(1))
    return best


@pytest.mark.parametrize("law", sorted(_seed002_best()))
def test_seed002_picks_give_their_recorded_criterion(built_fmus, law: str) -> None:
    from cosim.reproduce.builds import build_overrides
    from cosim.reproduce.entry import load_entry
    from cosim.reproduce.members import execute
    from cosim.run.scenario import load_scenario
    from cosim.run.simulate import ensure_built

    script = _script("seed002_tuning")
    entry = load_entry("seed002")
    run = next(r for r in entry.runs if r.name == law)
    own = {**run.overrides, **({f"{script.FMU}.build": "python"}
                               if law in script.PYTHON_CONTROLLER else {})}
    base = {**own, **build_overrides(run.scenario, own, entry.build)}
    ensure_built(load_scenario(run.scenario, base))
    picks = tomllib.loads(TUNING_FILE.read_text())[law]
    seeds = list(entry.ensemble.calibration_seeds)
    jobs = [((law, "picks", seed, 0), run.scenario,  # (row, point, seed, path 0: main)
             {**base, **{f"{script.FMU}.{k}": v for k, v in picks.items()},
              script.SEED_KEY: seed}) for seed in seeds]
    out = execute(jobs, 1, f"seed002 {law} picks", reference_path=False)
    c = script.criterion([out[(law, "picks", seed, 0)] for seed in seeds])
    recorded = _seed002_best()[law]
    assert abs(c - recorded) <= PRINTED, (
        f"{law}: its picks give criterion {c:.6f}, the tuning recorded {recorded}: the picks "
        "are stale; run `python papers/seed002/tuning.py` again")


@pytest.mark.parametrize("tracker", ["GPC", "LMI MPC"])
def test_seed003_picks_are_the_best_of_their_grid(built_fmus, tracker: str) -> None:
    import math

    from cosim.run.scenario import load_scenario

    script = _script("seed003_tuning")
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
