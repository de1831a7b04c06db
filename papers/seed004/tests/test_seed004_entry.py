"""Seed 004's timing claims: repeats of the nominal run, independent of K, no rounding rerun."""

from __future__ import annotations

from cosim.reproduce.entry import load_entry
from cosim.reproduce.members import claim_cases, members


def test_seed004_timing_claims_take_the_entrys_repeats_whatever_the_seeds() -> None:
    entry = load_entry("seed004")
    timing = [c for c in entry.claims if c.metric == "qp_cpu_time_total_s"]
    assert timing and all(c.ensemble == "repeat" for c in timing)
    assert entry.ensemble.repeats is not None
    assert (len(members(entry, "repeat", 2)) == len(members(entry, "repeat", 20))
            == entry.ensemble.repeats)
    rounding = {c.id: rnd for _v, c, _r, rnd, _k in claim_cases(entry, 2)}
    assert [rounding[c.id] for c in timing] == [False] * len(timing)
