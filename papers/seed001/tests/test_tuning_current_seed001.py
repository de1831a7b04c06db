"""Seed 001's generated tuning picks are today's code's (slow): each law's picked parameters
(``BEST`` in ``controllers/datadriven/tuned.py``), evaluated again by the criterion of
``papers/seed001/tuning.py`` (its core closed loops) on the calibration seeds, give the criterion
the script recorded beside them. A change to a law, a plant, the route or the master that moves
a criterion makes the picks stale: the failure says which script to run again (seed 002's and
003's picks are checked in their own folders' tests).

Tolerance: half a unit of the recorded criterion's 4th decimal (it is printed ``%.4f``); the
evaluation is the same deterministic computation as the script's, so on any machine it differs
from the recorded value only by that rounding (and floating-point rounding far below it)."""

from __future__ import annotations

from pathlib import Path

import pytest

from controllers.datadriven import tuned
from tests.paper_scripts import paper_script

PRINTED = 0.5e-4  # half a unit of the 4th decimal of the recorded criterion

pytestmark = pytest.mark.slow

PAPER = Path(__file__).resolve().parents[1]  # papers/seed001


@pytest.mark.parametrize("law", sorted(tuned.TUNED))
def test_seed001_picks_give_their_recorded_criterion(law: str) -> None:
    script = paper_script(PAPER / "tuning.py", "seed001_tuning")
    rows = [script.run((law, 0, tuned.TUNED[law], white, seed))
            for white in script.DISTURBANCES for seed in script.calibration_seeds()]
    c = script.criterion(rows)
    assert abs(c - tuned.BEST[law]) <= PRINTED, (
        f"{law}: its picks give criterion {c:.6f}, the tuning recorded {tuned.BEST[law]}: the "
        "picks are stale; run `python papers/seed001/tuning.py` again")
