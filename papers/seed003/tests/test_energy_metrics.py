"""Seed 003 summary metrics (papers/seed003/metrics.py): eq. 9 energies, per Table 2 phase, counted
up to the arrival; and the reproduce entry's derived saving rows."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from cosim import papers
from cosim.reproduce.entry import ReproduceError, load_entry
from cosim.reproduce.tables import derived_rows
from cosim.run.metrics import _arrival_index

CFG = {"energy_traction": "p.et", "energy_regen": "p.er", "energy_aux": "p.ea",
       "phase": "c.phase"}


def _frame() -> pd.DataFrame:
    """10 s: accelerate 0-3 s, run 3-6 s, brake 6-8 s, standing 8-10 s; 1 MW aux."""
    t = np.arange(11.0)
    v = np.array([0, 5, 10, 15, 15, 15, 15, 10, 0, 0, 0], dtype=float)
    phase = np.array([1, 1, 1, 2, 2, 2, 3, 3, 3, 3, 3], dtype=float)
    trac_power = np.where(phase == 1, 4e6, np.where(phase == 2, 2e6, 0.0))  # W, per interval
    regen_power = np.where(phase == 3, 3e6, 0.0)
    et = np.concatenate(([0.0], np.cumsum(trac_power[:-1])))
    er = np.concatenate(([0.0], np.cumsum(regen_power[:-1])))
    return pd.DataFrame({"time": t, "p.v": v, "p.et": et, "p.er": er, "p.ea": 1e6 * t,
                         "c.phase": phase})


def _energy(frame: pd.DataFrame, cfg: dict, arrival: int | None) -> dict:
    run = papers.RunRecord(frame=frame, summary=cfg, arrival_index=arrival)
    return papers.compute(["energy", "energy_phases"], run)


def test_energy_per_phase_sums_to_the_total_up_to_the_arrival() -> None:
    frame = _frame()
    arrival = _arrival_index(frame["p.v"].to_numpy())
    assert arrival == 8
    out = _energy(frame, CFG, arrival)
    assert out["energy_traction_mj"] == pytest.approx(3 * 4 + 3 * 2)
    assert out["energy_regen_mj"] == pytest.approx(2 * 3)  # braking 6-8 s only
    assert out["energy_aux_mj"] == pytest.approx(8.0)  # standing after 8 s not counted
    assert out["energy_net_mj"] == pytest.approx(18 - 6 + 8)
    assert out["energy_accelerate_mj"] == pytest.approx(12 + 3)
    assert out["energy_run_mj"] == pytest.approx(6 + 3)
    assert out["energy_brake_mj"] == pytest.approx(-6 + 2)
    total = sum(out[f"energy_{p}_mj"] for p in ("accelerate", "run", "brake"))
    assert total == pytest.approx(out["energy_net_mj"], rel=1e-12)


def test_still_moving_at_the_end_counts_the_whole_run_and_missing_columns_give_nothing() -> None:
    frame = _frame()
    frame["p.v"] = 1.0
    assert _arrival_index(frame["p.v"].to_numpy()) is None
    out = _energy(frame, CFG, None)
    assert out["energy_aux_mj"] == pytest.approx(10.0)
    assert _energy(frame, {"energy_traction": "p.et"}, None) == {}


def test_derived_saving_rows(tmp_path) -> None:
    entry = load_entry("seed003")
    names = entry.run_names()
    summaries = {n: {"energy_net_mj": 100.0, "energy_run_mj": 50.0,
                     "energy_traction_mj": 80.0} for n in names}
    summaries["Eco (GPC)"] = {"energy_net_mj": 82.0, "energy_run_mj": 40.0,
                              "energy_traction_mj": 70.0}
    rows = {r.run: r for r in derived_rows(entry, summaries)}
    text = rows["eco saving, total (paper text)"]
    assert text.ours == pytest.approx(18.0) and text.paper == pytest.approx(17.7)
    assert rows["eco saving, run phase"].ours == pytest.approx(20.0)
    bad = tmp_path / "bad.toml"
    bad.write_text(entry.path.read_text().replace('kind = "saving_percent"',
                                                  'kind = "ratio"', 1))
    with pytest.raises(ReproduceError, match="kind 'ratio'"):
        load_entry(str(bad))
