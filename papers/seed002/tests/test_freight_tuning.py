"""Seed 002's tuning of every freight law's own gains (papers/seed002/tuning.py): the
generated file holds exactly the gains the protocol declares, inside their boxes; the four
laws' FMUs take their picks as defaults and the other rows take theirs through the entry's
``[[runs]] tuned``; the protocol's search points stay in their boxes; a ``tuned`` reference that
cannot be read is refused naming the entry, the run and the value."""

from __future__ import annotations

import csv
import importlib.util
import math
import re
import sys
from pathlib import Path

import numpy as np
import pytest

from controllers.common.freight_tuning import TUNING_FILE
from controllers.fuzzy.fuzzy_pid import FuzzyPidParams
from controllers.pid.freight_pid import FreightPidParams
from controllers.preview.preview import PreviewParams
from controllers.smc.sliding_mode import SlidingModeParams
from cosim.fmu.declare import parameters
from cosim.reproduce.entry import ReproduceError, load_entry

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib  # type: ignore[no-redef]

PAPER = Path(__file__).resolve().parents[1]  # papers/seed002
_spec = importlib.util.spec_from_file_location("seed002_tuning", PAPER / "tuning.py")
tuning = importlib.util.module_from_spec(_spec)
sys.modules["seed002_tuning"] = tuning
_spec.loader.exec_module(tuning)

PICKS = tomllib.loads(TUNING_FILE.read_text())
PARAMS = {"Preview": PreviewParams, "SMC": SlidingModeParams,
          "SMC, boundary layer": SlidingModeParams, "FPID": FuzzyPidParams,
          "FPID + feedforward": FuzzyPidParams, "PID": FreightPidParams}
MAIN = ("Preview", "SMC", "FPID", "PID")  # the rows that run their FMU's defaults


def _declared(cls) -> dict:
    return {v.name: v for v in parameters(cls())}


def test_the_file_holds_every_declared_gain_of_every_row_inside_its_box() -> None:
    assert set(PICKS) == set(tuning.GAINS) == set(PARAMS)
    for law, gains in tuning.GAINS.items():
        names = {g.name for g in gains} | {n for g in gains for n in g.also}
        assert set(PICKS[law]) == names, law
        declared = _declared(PARAMS[law])
        for g in gains:
            value = PICKS[law][g.name]
            assert g.lo <= value <= g.hi, (law, g.name, value)
            assert isinstance(value, int) == g.integer, (law, g.name)
            for name in (g.name, *g.also):
                assert name in declared, (law, name)  # a parameter its FMU declares
                assert PICKS[law][name] == value


@pytest.mark.parametrize("law", MAIN)
def test_the_laws_fmus_default_to_their_picks(law: str) -> None:
    declared = _declared(PARAMS[law])
    for name, value in PICKS[law].items():
        assert declared[name].start == value, (law, name)


def test_the_other_rows_run_their_own_picks_and_their_own_set() -> None:
    runs = {r.name: r for r in load_entry("seed002").runs}
    for law in set(tuning.GAINS) - set(MAIN):
        for name, value in PICKS[law].items():
            assert runs[law].overrides[f"controller.{name}"] == value, (law, name)
    assert runs["FPID + feedforward"].overrides["controller.reference_feedforward"] is True
    for law in MAIN:  # the FMU's defaults: nothing of the file repeated as an override
        assert not set(runs[law].overrides) & {f"controller.{n}" for n in PICKS[law]}


def test_a_gain_maps_the_unit_interval_onto_its_box() -> None:
    log = tuning.Gain("h", 1e2, 1e6)
    assert (log.value(0.0), log.value(0.5), log.value(1.0)) == (100.0, 1e4, 1e6)
    lin = tuning.Gain("w", 0.0, 1.0, log=False)
    assert lin.value(0.25) == 0.25
    m = tuning.Gain("M_R", 25, 400, integer=True, also=("M_d",))
    values = tuning.parameters((m, lin), np.array([1.0, 0.5]))
    assert values == {"M_R": 400, "M_d": 400, "w": 0.5}


@pytest.mark.parametrize("best", [np.array([0.0, 1.0, 0.3]), np.array([0.99, 0.5, 0.01])])
def test_each_stage_searches_a_box_half_as_wide_around_the_best_inside_the_cube(best) -> None:
    assert tuning.BUDGET == sum(tuning.STAGES)
    whole = tuning.stage_points(0, 3, None)
    assert whole.shape == (tuning.STAGES[0], 3) and np.all((whole >= 0) & (whole <= 1))
    for stage in range(1, len(tuning.STAGES)):
        points = tuning.stage_points(stage, 3, best)
        width = 0.5 ** stage
        assert points.shape == (tuning.STAGES[stage], 3)
        assert np.all((points >= 0) & (points <= 1))
        low, high = points.min(axis=0), points.max(axis=0)
        assert np.all(high - low <= width)
        # the box holds the best point (moved inside the cube, not shrunk)
        box_low = np.clip(best - width / 2, 0.0, 1.0 - width)
        assert np.all((box_low <= best) & (best <= box_low + width))
        assert np.all((points >= box_low) & (points <= box_low + width))


def test_the_criterion_weighs_both_errors_alike_and_a_failed_run_loses() -> None:
    a = {"train_mean_speed_rmse_kmh": 0.1, "speed_rmse_kmh": 0.4}
    b = {"train_mean_speed_rmse_kmh": 0.4, "speed_rmse_kmh": 0.1}
    assert tuning.criterion([a]) == tuning.criterion([b]) == pytest.approx(np.log(0.04))
    assert tuning.criterion([a, None]) == np.inf


ENTRY = """
title = "Test entry"
[[runs]]
name = "SMC"
scenario = "seed002_freight_smc"
set = {{ "controller.q" = 0.5 }}
tuned = {{ controller = "{ref}" }}
"""


def test_tuned_values_sit_between_the_entrys_set_and_the_runs_own(tmp_path: Path) -> None:
    picks = tmp_path / "picks.toml"
    picks.write_text('["SMC, x"]\nq = 0.2\neps = 0.01\n')
    entry = tmp_path / "e.toml"
    entry.write_text('set = { "controller.eps" = 0.9, "plant.v0" = 1.0 }\n'
                     + ENTRY.format(ref=f"{picks}#SMC, x"))
    (run,) = load_entry(str(entry)).runs
    assert run.overrides == {"plant.v0": 1.0, "controller.eps": 0.01, "controller.q": 0.5}


@pytest.mark.parametrize("ref, message", [
    ("{picks}", 'expected "FILE#TABLE"'),
    ("{picks}#", 'expected "FILE#TABLE"'),
    ("{tmp}/none.toml#SMC", "no file"),
    ("{picks}#PID", "has no table [PID] of values (its tables: ['SMC'])"),
])
def test_a_tuned_reference_that_cannot_be_read_is_refused(tmp_path: Path, ref: str,
                                                          message: str) -> None:
    picks = tmp_path / "picks.toml"
    picks.write_text("[SMC]\nq = 0.2\n")
    ref = ref.format(picks=picks, tmp=tmp_path)
    entry = tmp_path / "e.toml"
    entry.write_text(ENTRY.format(ref=ref))
    with pytest.raises(ReproduceError, match=re.escape(message)) as err:
        load_entry(str(entry))
    assert f"{entry}: [[runs]] #1: tuned.controller = {ref!r}" in str(err.value)


def test_a_pick_at_an_end_of_its_box_is_flagged() -> None:
    g = tuning.Gain("h", 1e2, 1e6)
    assert g.at_edge(100.0) and g.at_edge(1e6) and not g.at_edge(1e4)
    assert g.unit(g.value(0.3)) == pytest.approx(0.3, rel=1e-5)  # value() keeps 6 digits


def test_picks_from_a_log_are_each_laws_first_best(tmp_path: Path) -> None:
    """The log a run writes gives back, per law, the first point of the lowest criterion."""
    names = list(dict.fromkeys(n for gains in tuning.GAINS.values() for g in gains
                               for n in (g.name, *g.also)))
    rows = [["law", "stage", "point", *names, "criterion"]]
    want = {}
    for law, gains in tuning.GAINS.items():
        for i, (u, c) in enumerate([(0.1, -1.0), (0.4, -2.0), (0.7, -2.0), (0.9, math.inf)]):
            values = tuning.parameters(gains, np.full(len(gains), u))
            rows.append([law, 1, i, *(values.get(n, "") for n in names), c])
            if i == 1:
                want[law] = values
    log = tmp_path / "log.csv"
    with log.open("w", newline="") as f:
        csv.writer(f).writerows(rows)
    picks, best = tuning.picks_from_log(log)
    assert picks == want and best == dict.fromkeys(tuning.GAINS, -2.0)
    assert all(type(picks[law][g.name]) is (int if g.integer else float)
               for law, gains in tuning.GAINS.items() for g in gains)
    with log.open("w", newline="") as f:
        csv.writer(f).writerows(row for row in rows if row[0] != "PID")
    with pytest.raises(SystemExit, match=re.escape("no finished evaluation of ['PID']")):
        tuning.picks_from_log(log)
