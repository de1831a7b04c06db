"""Seed 002's generated tuning picks are today's code's (slow): each freight law's picks in
``controllers/common/freight_tuning.toml``, run again through the FMU runs of
``papers/seed002/tuning.py`` on the calibration seeds, give the criterion recorded on the
``# criterion`` line of its table. A change to a law, a plant, the route or the master that
moves a criterion makes the picks stale: the failure says which script to run again.

Tolerance: half a unit of the recorded criterion's 4th decimal (it is printed ``%.4f``); the
evaluation is the same deterministic computation as the script's, so on any machine it differs
from the recorded value only by that rounding (and floating-point rounding far below it)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from controllers.common.freight_tuning import TUNING_FILE
from tests.paper_scripts import paper_script

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib  # type: ignore[no-redef]

PRINTED = 0.5e-4  # half a unit of the 4th decimal of the recorded criterion

pytestmark = pytest.mark.slow

PAPER = Path(__file__).resolve().parents[1]  # papers/seed002


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

    script = paper_script(PAPER / "tuning.py", "seed002_tuning")
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
