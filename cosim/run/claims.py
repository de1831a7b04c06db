"""A paper's claims as data, tested over seed ensembles (``[ensemble]`` and ``[[claims]]`` of a
reproduction entry; schema in the module docstring of :mod:`cosim.run.reproduce`).

Statistics: per metric the median over the ensemble and its 95 % bootstrap CI; per pairwise
claim the paired difference (same seed / same mismatch sample), its median and 95 % CI and
"A better on k of K". The bootstrap is :func:`scipy.stats.bootstrap` (percentile method, the
median being a non-smooth statistic for which BCa's jackknife acceleration is unreliable on
tied samples; a fixed ``random_state`` so the same runs give the same CI).

Verdicts: ``holds`` (CI strictly on the claimed side of 0 / the threshold / inside the range),
``fails`` (strictly on the other side / outside the range), ``inconclusive`` otherwise.
Degenerate cases give a stated verdict: a missing or NaN metric on any member ->
inconclusive ("metric missing"); all samples equal (a deterministic run) -> the CI is that
value; fewer than 3 distinct members and not all equal -> inconclusive ("K < 3").
A verdict that differs on the perturbed floating-point rerun -> ``rounding-sensitive``.

Ensemble kinds of a claim: ``disturbance`` (member i: report seed i), ``mismatch`` (member i:
plant-mismatch sample i), ``repeat`` (member i < ``[ensemble] repeats``: the same nominal
deterministic run again, for metrics that vary run to run only through measurement, CPU and
wall times; pair i is repeat index i of A and of B; no perturbed floating-point rerun, whose
rounding verdict does not apply: ``rounding_robust`` is None).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from typing import Any

import numpy as np

CLAIM_KINDS = ("less", "greater", "below", "above", "inside")
ENSEMBLES = ("disturbance", "mismatch", "repeat")
ORIGINS = ("paper", "ours")
_CLAIM_KEYS = {"id", "source", "text", "paper", "metric", "kind", "runs", "threshold", "range",
               "ensemble", "origin"}
_ENSEMBLE_KEYS = {"seed_key", "report_seeds", "calibration_seeds", "perturb", "perturb_seed",
                  "rounding_perturb", "rounding_reference_path", "repeats"}
_VARIANT_KEYS = {"name", "text", "replace", "rounding", "seeds"}
ROUNDING_RELATIVE = 1e-12  # relative change of each [ensemble].rounding_perturb parameter
CONFIDENCE = 0.95
N_RESAMPLES = 9999
BOOTSTRAP_SEED = 12345


class ClaimsError(ValueError):
    """Claims data that cannot be used (the message names the file, key and value)."""


@dataclass
class Ensemble:
    """How an entry's runs are varied (see :mod:`cosim.run.reproduce`)."""

    seed_key: str | None = None
    report_seeds: list[int] = field(default_factory=lambda: list(range(1, 21)))
    calibration_seeds: list[int] = field(default_factory=list)
    perturb: list[str] = field(default_factory=list)
    perturb_seed: int = 0
    rounding_perturb: list[str] = field(default_factory=list)
    rounding_reference_path: bool = True
    repeats: int | None = None  # members of a "repeat" claim (None: no such claim allowed)


def parse_seeds(where: str, key: str, value: Any) -> list[int]:
    """``"1..20"``, ``"1..5, 9"`` or a list of integers -> the seeds (errors name the key)."""
    if isinstance(value, list) and all(isinstance(v, int) and not isinstance(v, bool)
                                       for v in value):
        seeds = list(value)
    elif isinstance(value, str):
        seeds = []
        for part in value.replace(" ", "").split(","):
            m = re.fullmatch(r"(-?\d+)(?:\.\.(-?\d+))?", part)
            if not m:
                raise ClaimsError(f"{where}: {key} = {value!r}: expected 'A..B', 'A, B' or a "
                                  "list of integers")
            lo, hi = int(m[1]), int(m[2] if m[2] is not None else m[1])
            if hi < lo:
                raise ClaimsError(f"{where}: {key} = {value!r}: empty range {lo}..{hi}")
            seeds += list(range(lo, hi + 1))
    else:
        raise ClaimsError(f"{where}: {key} = {value!r}: expected 'A..B' or a list of integers")
    if len(set(seeds)) != len(seeds) or not seeds:
        raise ClaimsError(f"{where}: {key} = {value!r}: seeds must be distinct and not empty")
    return seeds


def check_ensemble(where: str, data: dict[str, Any] | None) -> Ensemble:
    """The ``[ensemble]`` table, checked (calibration and report seeds disjoint)."""
    from cosim.run.perturb import parse_perturb

    if data is None:
        return Ensemble()
    unknown = sorted(set(data) - _ENSEMBLE_KEYS)
    if unknown:
        raise ClaimsError(f"{where}: [ensemble]: unknown key(s) {unknown} (allowed: "
                          f"{sorted(_ENSEMBLE_KEYS)})")
    ens = Ensemble()
    if "seed_key" in data:
        if not (isinstance(data["seed_key"], str) and "." in data["seed_key"]):
            raise ClaimsError(f"{where}: [ensemble] seed_key = {data['seed_key']!r}: expected "
                              "an override key FMU.PARAMETER")
        ens.seed_key = data["seed_key"]
    if "report_seeds" in data:
        ens.report_seeds = parse_seeds(f"{where}: [ensemble]", "report_seeds",
                                       data["report_seeds"])
    if "calibration_seeds" in data:
        ens.calibration_seeds = parse_seeds(f"{where}: [ensemble]", "calibration_seeds",
                                            data["calibration_seeds"])
    both = sorted(set(ens.report_seeds) & set(ens.calibration_seeds))
    if both:
        raise ClaimsError(f"{where}: [ensemble]: calibration_seeds and report_seeds share "
                          f"{both}: tuning seeds must be disjoint from report seeds")
    for key in ("perturb", "rounding_perturb"):
        value = data.get(key, [])
        if not (isinstance(value, list) and all(isinstance(v, str) for v in value)):
            raise ClaimsError(f"{where}: [ensemble] {key} = {value!r}: expected a list of "
                              "strings")
    try:
        parse_perturb(data.get("perturb", []))
    except ValueError as err:
        raise ClaimsError(f"{where}: [ensemble] perturb: {err}") from err
    ens.perturb = list(data.get("perturb", []))
    for key in data.get("rounding_perturb", []):
        if "." not in key:
            raise ClaimsError(f"{where}: [ensemble] rounding_perturb: {key!r} is not "
                              "FMU.PARAMETER")
    ens.rounding_perturb = list(data.get("rounding_perturb", []))
    ref_path = data.get("rounding_reference_path", True)
    if not isinstance(ref_path, bool):
        raise ClaimsError(f"{where}: [ensemble] rounding_reference_path = {ref_path!r}: "
                          "expected true or false")
    if not ref_path and not ens.rounding_perturb:
        raise ClaimsError(f"{where}: [ensemble] rounding_reference_path = false needs "
                          "rounding_perturb: the rerun would repeat the main path")
    ens.rounding_reference_path = ref_path
    seed = data.get("perturb_seed", 0)
    if isinstance(seed, bool) or not isinstance(seed, int):
        raise ClaimsError(f"{where}: [ensemble] perturb_seed = {seed!r}: expected an integer")
    ens.perturb_seed = seed
    if "repeats" in data:
        rep = data["repeats"]
        if isinstance(rep, bool) or not isinstance(rep, int) or rep < 1:
            raise ClaimsError(f"{where}: [ensemble] repeats = {rep!r}: expected an integer "
                              ">= 1 (the repetitions of a 'repeat' claim's nominal run)")
        ens.repeats = rep
    return ens


def check_claims(where: str, claims: list[dict[str, Any]], run_names: list[str],
                 ens: Ensemble) -> list[dict[str, Any]]:
    """The ``[[claims]]`` tables, checked against the entry's run names and ensemble."""
    ids: set[str] = set()
    for i, claim in enumerate(claims):
        at = f"{where}: [[claims]] #{i + 1}"
        unknown = sorted(set(claim) - _CLAIM_KEYS)
        if unknown:
            raise ClaimsError(f"{at}: unknown key(s) {unknown} (allowed: {sorted(_CLAIM_KEYS)})")
        missing = [k for k in ("id", "text", "metric", "kind", "runs") if k not in claim]
        if missing:
            raise ClaimsError(f"{at}: missing key(s) {missing}")
        cid = claim["id"]
        if not (isinstance(cid, str) and re.fullmatch(r"[a-z0-9_]+", cid)):
            raise ClaimsError(f"{at}: id = {cid!r}: expected [a-z0-9_]+")
        if cid in ids:
            raise ClaimsError(f"{at}: id = {cid!r} repeats")
        ids.add(cid)
        at = f"{where}: [[claims]] {cid!r}"
        kind = claim["kind"]
        if kind not in CLAIM_KINDS:
            raise ClaimsError(f"{at}: kind = {kind!r} (known: {CLAIM_KINDS})")
        runs = claim["runs"]
        need = 2 if kind in ("less", "greater") else 1
        if not (isinstance(runs, list) and len(runs) == need):
            raise ClaimsError(f"{at}: runs = {runs!r}: kind {kind!r} compares {need} run(s)")
        for run in runs:
            if run not in run_names:
                raise ClaimsError(f"{at}: runs: {run!r} is not one of the entry's [[runs]] "
                                  f"{run_names}")
        if kind in ("below", "above"):
            thr = claim.get("threshold")
            if isinstance(thr, bool) or not isinstance(thr, (int, float)):
                raise ClaimsError(f"{at}: threshold = {thr!r}: kind {kind!r} needs a number")
        if kind == "inside":
            band = claim.get("range")
            if not (isinstance(band, list) and len(band) == 2
                    and all(isinstance(v, (int, float)) for v in band) and band[0] <= band[1]):
                raise ClaimsError(f"{at}: range = {band!r}: kind 'inside' needs [low, high]")
        ensemble = claim.get("ensemble", "disturbance")
        if ensemble not in ENSEMBLES:
            raise ClaimsError(f"{at}: ensemble = {ensemble!r} (known: {ENSEMBLES})")
        if ensemble == "mismatch" and not ens.perturb:
            raise ClaimsError(f"{at}: ensemble = 'mismatch' needs [ensemble] perturb")
        if ensemble == "repeat" and ens.repeats is None:
            raise ClaimsError(f"{at}: ensemble = 'repeat' needs [ensemble] repeats (the "
                              "number of repetitions of the nominal run)")
        if claim.get("origin", "paper") not in ORIGINS:
            raise ClaimsError(f"{at}: origin = {claim['origin']!r} (known: {ORIGINS})")
    return claims


def check_variants(where: str, variants: list[dict[str, Any]], run_names: list[str]
                   ) -> list[dict[str, Any]]:
    """The ``[[variants]]`` tables: each names the runs that replace others in every claim
    (an alternative reading or a mechanism removed), checked against the entry's runs."""
    names: set[str] = set()
    for i, var in enumerate(variants):
        at = f"{where}: [[variants]] #{i + 1}"
        unknown = sorted(set(var) - _VARIANT_KEYS)
        if unknown:
            raise ClaimsError(f"{at}: unknown key(s) {unknown} (allowed: "
                              f"{sorted(_VARIANT_KEYS)})")
        missing = [k for k in ("name", "replace") if k not in var]
        if missing:
            raise ClaimsError(f"{at}: missing key(s) {missing}")
        if not isinstance(var["name"], str) or var["name"] in names or var["name"] == "main":
            raise ClaimsError(f"{at}: name = {var['name']!r}: a new name other than 'main'")
        names.add(var["name"])
        rep = var["replace"]
        if not (isinstance(rep, dict) and rep):
            raise ClaimsError(f"{at}: replace = {rep!r}: expected a table run -> run")
        for old, new in rep.items():
            for run in (old, new):
                if run not in run_names:
                    raise ClaimsError(f"{at}: replace: {run!r} is not one of the entry's "
                                      f"[[runs]]")
        n = var.get("seeds")
        if n is not None and (isinstance(n, bool) or not isinstance(n, int) or n < 1):
            raise ClaimsError(f"{at}: seeds = {n!r}: expected an integer >= 1 (the first "
                              "report seeds, at most --seeds)")
        if not isinstance(var.get("rounding", False), bool):
            raise ClaimsError(f"{at}: rounding = {var['rounding']!r}: expected true or false")
    return variants


def variant_runs(claim: dict[str, Any], variant: dict[str, Any]) -> list[str] | None:
    """The claim's runs under ``variant`` (None: the variant replaces none of them)."""
    rep = variant["replace"]
    if not any(r in rep for r in claim["runs"]):
        return None
    return [rep.get(r, r) for r in claim["runs"]]


def median_ci(values: np.ndarray) -> tuple[float, float, float, str]:
    """(median, CI low, CI high, note) of ``values`` (see the module doc for the degenerate
    cases; NaN bounds when no CI can be given)."""
    values = np.asarray(values, dtype=float)
    if values.size == 0 or np.isnan(values).any():
        return math.nan, math.nan, math.nan, "metric missing"
    med = float(np.median(values))
    if np.all(values == values[0]):
        return med, med, med, "all equal" if values.size > 1 else "one run"
    if values.size < 3:
        return med, math.nan, math.nan, "K < 3"
    from scipy.stats import bootstrap

    res = bootstrap((values,), np.median, confidence_level=CONFIDENCE, method="percentile",
                    n_resamples=N_RESAMPLES, random_state=np.random.default_rng(BOOTSTRAP_SEED))
    return med, float(res.confidence_interval.low), float(res.confidence_interval.high), ""


def ratio_ci(a: np.ndarray, b: np.ndarray) -> tuple[float, float, float]:
    """(median(a) / median(b), CI low, CI high) over independent repetitions ``a`` and ``b``
    (e.g. the timing repeats of two runs): percentile bootstrap resampling each side on its
    own; NaN bounds with fewer than 3 repetitions on a side or a zero median."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    if a.size == 0 or b.size == 0 or np.isnan(a).any() or np.isnan(b).any():
        return math.nan, math.nan, math.nan
    mb = float(np.median(b))
    if mb == 0.0:
        return math.nan, math.nan, math.nan
    ratio = float(np.median(a)) / mb
    if a.size < 3 or b.size < 3:
        return ratio, math.nan, math.nan
    from scipy.stats import bootstrap

    def stat(x: np.ndarray, y: np.ndarray, axis: int = -1) -> np.ndarray:
        return np.median(x, axis=axis) / np.median(y, axis=axis)

    res = bootstrap((a, b), stat, confidence_level=CONFIDENCE, method="percentile",
                    n_resamples=N_RESAMPLES, random_state=np.random.default_rng(BOOTSTRAP_SEED))
    return ratio, float(res.confidence_interval.low), float(res.confidence_interval.high)


def verdict(claim: dict[str, Any], a: np.ndarray, b: np.ndarray | None = None
            ) -> dict[str, Any]:
    """Evaluate one claim on its members: ``a`` (runs[0]) and, for less/greater, ``b``
    (runs[1]) paired by index. Returns median/CI of the tested quantity, k of K, verdict."""
    kind = claim["kind"]
    a = np.asarray(a, dtype=float)
    if kind in ("less", "greater"):
        assert b is not None
        x = a - np.asarray(b, dtype=float)  # paired difference
        low_side, high_side = 0.0, 0.0
        better = x < 0 if kind == "less" else x > 0
    elif kind in ("below", "above"):
        x = a
        low_side = high_side = float(claim["threshold"])
        better = x < low_side if kind == "below" else x > low_side
    else:
        x = a
        low_side, high_side = (float(v) for v in claim["range"])
        better = (x >= low_side) & (x <= high_side)
    med, lo, hi, note = median_ci(x)
    out = {"median": med, "ci_low": lo, "ci_high": hi, "k": int(np.sum(better)),
           "K": int(x.size), "note": note}
    if kind in ("less", "greater"):
        out.update(a_median=float(np.median(a)) if a.size else math.nan,
                   b_median=float(np.median(b)) if np.size(b) else math.nan)
    if math.isnan(lo) or math.isnan(hi):
        out["verdict"] = "inconclusive"
        return out
    if kind in ("less", "below"):
        v = "holds" if hi < low_side else "fails" if lo > low_side else "inconclusive"
    elif kind in ("greater", "above"):
        v = "holds" if lo > low_side else "fails" if hi < low_side else "inconclusive"
    else:
        v = ("holds" if lo >= low_side and hi <= high_side
             else "fails" if hi < low_side or lo > high_side else "inconclusive")
    out["verdict"] = v
    return out


def with_rounding(main: dict[str, Any], perturbed: dict[str, Any] | None) -> dict[str, Any]:
    """``main`` with ``rounding_verdict``, ``rounding_robust`` and the final ``verdict``
    (``rounding-sensitive`` when the perturbed floating-point path's verdict differs)."""
    out = dict(main, main_verdict=main["verdict"])
    if perturbed is None:
        out.update(rounding_verdict=None, rounding_robust=None)
        return out
    same = perturbed["verdict"] == main["verdict"]
    out.update(rounding_verdict=perturbed["verdict"], rounding_robust=same)
    if not same:
        out["verdict"] = "rounding-sensitive"
    return out


def ours_text(row: dict[str, Any]) -> str:
    """``median [low, high]`` of the tested quantity (``-`` where unknown)."""
    def f(v: float) -> str:
        return "-" if v is None or (isinstance(v, float) and math.isnan(v)) else f"{v:.4g}"
    text = f"{f(row['median'])} [{f(row['ci_low'])}, {f(row['ci_high'])}]"
    return f"{text} ({row['note']})" if row.get("note") else text
