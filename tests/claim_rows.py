"""Claim rows for the tests of the pages: a :class:`cosim.reproduce.verdicts.ClaimRow` from the
flat fields of one ``claims.csv`` row (the claim's and its main path's), without running a
claim."""

from __future__ import annotations

import dataclasses

from cosim.reproduce.claims import Claim
from cosim.reproduce.stats import Rounded, Verdict
from cosim.reproduce.verdicts import ClaimRow

DEFAULTS: dict[str, object] = {
    "id": "a_below_b", "text": "A stops closer than B", "quantifier": "typical",
    "runs": "A vs B", "metric": "stop_error_m", "ensemble": "disturbance", "origin": "paper",
    "verdict": "holds", "k": 20, "K": 20, "kind": "less", "paper": "", "source": "",
    "rounding_robust": True}
CLAIM_FIELDS = {f.name for f in dataclasses.fields(Claim)}
VERDICT_FIELDS = {f.name for f in dataclasses.fields(Verdict)}


def claim_row(**fields: object) -> ClaimRow:
    """The row of the claim and main-path verdict ``fields`` name (``runs``: "A vs B";
    ``rounding_robust``: True, False (a perturbed path that disagrees) or None (no rerun);
    ``adjusted``: the verdict after the multiplicity adjustment, "" for none)."""
    f = {**DEFAULTS, **fields}
    runs = str(f["runs"]).split(" vs ")
    claim = Claim(**{k: v for k, v in f.items() if k in CLAIM_FIELDS and k != "runs"},
                  runs=runs)
    main = Verdict(**{k: v for k, v in f.items() if k in VERDICT_FIELDS})
    robust = f["rounding_robust"]
    perturbed = () if robust is None else (
        main if robust else dataclasses.replace(main, verdict=f"not {main.verdict}"),)
    return ClaimRow(claim=claim, runs=runs, result=Rounded(main, perturbed),
                    variant=fields.get("variant"), adjusted=str(f.get("adjusted", "")))
