"""A paper's claims as data, tested over seed ensembles (``[ensemble]`` and ``[[claims]]`` of a
reproduction entry; schema: :mod:`cosim.reproduce.entry`).

Each claim compares, per member, a tested quantity with its claimed side: ``less`` /
``greater`` the paired difference A - B (same seed / same mismatch sample) with 0, ``equal``
that difference with the band +-``margin`` x |median of B| (an equivalence: "no longer
improves noticeably", "levels off"), ``below`` / ``above`` a metric with ``threshold``,
``inside`` a metric with ``range``. Its
``quantifier`` says what the paper's sentence asserts about the runs:

- ``every`` (universal: "stops within +-50 cm", "in every speed class"): holds only if every
  member is on the claimed side, fails on the first that is not; the row gives the count
  and the worst member, and the one-sided Clopper-Pearson lower bound of the share of runs
  the K members support (``scipy.stats.binomtest``). A counterexample is not a statistical
  inference, so these claims take no part in the multiplicity adjustment.
- ``share`` (at least ``share`` = p of the runs): exact one-sided binomial tests of k of K
  against p (``scipy.stats.binomtest``), each at (1 - ``CONFIDENCE``) / 2.
- ``typical`` (the usual run: "A tracks better than B"): the sign test on the median
  (``scipy.stats.quantile_test``, exact and distribution-free), each direction at
  (1 - ``CONFIDENCE``) / 2, so a decision is the median's exact 95 % CI (order statistics,
  shown) strictly on one side; ``inside`` and ``equal`` hold when both edges' tests decide
  (an intersection-union test, for ``equal`` the two one-sided tests of equivalence), and
  fail when one edge's test decides the other way (the median outside the band).

The default quantifier is ``every`` for ``below`` / ``above`` / ``inside`` (the papers state
such bounds as requirements each run meets) and ``typical`` for ``less`` / ``greater`` /
``equal`` (``equal`` takes ``typical`` only).

Verdicts: ``holds``, ``fails``, ``inconclusive`` (the test decides neither way), ``no effect``
(a ``typical`` less / greater claim with a ``margin``: the test decides neither way and the
exact CI of the median paired difference lies within +-``margin`` x |median of B|, the
smallest effect the claim calls material, stated with it: an equivalence decision, so "no
effect" is told apart from "undecided"), or
``insufficient`` where K members cannot decide at the confidence whatever they show (the
note says which K would). Degenerate cases: a missing or NaN metric on any member ->
inconclusive ("metric missing"); all members equal (a deterministic result) -> decided by
that value. A verdict that differs on the perturbed floating-point rerun ->
``rounding-sensitive``.

Multiplicity: the claims of one paper are a family; their p-values (two-sided: twice the
smaller one-sided one) are adjusted by Benjamini-Hochberg (``scipy.stats.
false_discovery_control``), false discovery rate 1 - ``CONFIDENCE``; the ``adjusted``
verdict keeps a decision only where the adjusted p-value is below that rate
(:func:`adjust`).

Ensemble kinds of a claim: ``disturbance`` (member i: report seed i), ``mismatch`` (member i:
plant-mismatch sample i), ``repeat`` (member i < ``[ensemble] repeats``: the same nominal
deterministic run again, for metrics that vary run to run only through measurement, CPU and
wall times; pair i is repeat index i of A and of B; no perturbed floating-point rerun, whose
rounding verdict does not apply: ``rounding_robust`` is None).
"""

from __future__ import annotations

import itertools
import math
import numbers
import re
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from cosim.run.console import decimal_exponent
from cosim.run.perturbation import parse_perturb

CLAIM_KINDS = ("less", "greater", "equal", "below", "above", "inside")
PAIRED_KINDS = ("less", "greater", "equal")  # comparing two runs, paired by member
QUANTIFIERS = ("every", "share", "typical")
ENSEMBLES = ("disturbance", "mismatch", "repeat")
ORIGINS = ("paper", "ours", "sanity")  # the paper's statement, ours, a check of the setup
REQUIRED = "required"
# The keys of the claims' tables: key -> (type, default, meaning); the schema page
# (docs/reproduce_schema.md) is written from them.
ENSEMBLE_KEYS: dict[str, tuple[str, str, str]] = {
    "seed_key": ("a string FMU.PARAMETER", "none", "the override key taking a member's seed "
                 "(none: no random input; a \"disturbance\" claim is then one run)"),
    "report_seeds": ("\"A..B\", \"A..B, C\" or a list of integers", "\"1..20\"",
                     "the seeds of the members; ``--seeds K`` takes the first K"),
    "calibration_seeds": ("as report_seeds", "none", "the seeds used for tuning only; "
                          "disjoint from report_seeds (checked)"),
    "perturb": ("a list of strings", "[]", "the plant-mismatch distribution of a "
                "\"mismatch\" claim, as ``--perturb`` (``plant.mass=+-10%``)"),
    "perturb_seed": ("an integer", "0", "the seed of the mismatch draws"),
    "rounding_perturb": ("a list of strings FMU.PARAMETER", "[]", "parameters scaled by "
                         "1 + 1e-12 on the perturbed floating-point rerun"),
    "rounding_perturb_second": ("a list of strings FMU.PARAMETER", "[]", "parameters scaled "
                                "by 1 + 1e-12 on a second perturbed rerun, independent of the "
                                "first (other parameters; never the numpy reference path); "
                                "none: one rerun"),
    "rounding_reference_path": ("true or false", "true", "the rerun also takes the plants' "
                                "numpy reference path (``ATO_COSIM_NO_KERNELS=1``); false "
                                "keeps the compiled kernels (rounding_perturb alone "
                                "perturbs it)"),
    "repeats": ("an integer >= 1", "none", "the members of a \"repeat\" claim: repetitions of "
                "the nominal run, whatever ``--seeds`` (no rounding rerun)"),
    "members": ("an integer in [1, report seeds]", "20, or every report seed if fewer",
                "K a published page needs"),
}
CLAIM_KEYS: dict[str, tuple[str, str, str]] = {
    "id": ("a string [a-z0-9_]+", REQUIRED, "the claim's id, unique in the entry"),
    "text": ("a string", REQUIRED, "the claim in words (\"ISMPC has a lower MSE than ISMC\")"),
    "metric": ("a string", REQUIRED, "the summary key tested ('.' for a nested key; a bool "
               "counts 1 / 0)"),
    "kind": ("less | greater | equal | below | above | inside", REQUIRED,
             "less / greater: runs[0] against runs[1], paired by member; equal: their "
             "difference within +-margin x |median of runs[1]|; below / above: runs[0] "
             "against threshold; inside: runs[0] within range"),
    "runs": ("a list of strings", REQUIRED, "the ``[[runs]]`` names compared: two for less / "
             "greater / equal, one otherwise"),
    "threshold": ("a number", "none", "below / above: the bound, in the metric's unit"),
    "range": ("[low, high]", "none", "inside: the band, in the metric's unit"),
    "quantifier": ("every | share | typical", "every for below / above / inside, typical for "
                   "less / greater / equal", "what the claim asserts of the runs "
                   "(:mod:`cosim.run.claims`)"),
    "share": ("a number in (0, 1)", "none", "with quantifier share: at least this fraction "
              "of the runs"),
    "transform": ("abs", "none", "the metric's absolute value per member"),
    "ensemble": ("disturbance | mismatch | repeat", "disturbance", "the members: the report "
                 "seeds, the perturb samples, or the nominal run ``[ensemble] repeats`` times "
                 "(paired by repeat index: CPU and wall time claims)"),
    "origin": ("paper | ours | sanity", "paper", "whose claim: the paper's, ours, or a check "
               "of the setup"),
    "source": ("a string", "\"\"", "where the paper makes it (\"Table 2\")"),
    "paper": ("a string", "\"\"", "the paper's value(s), as text"),
    "each": ("a table placeholder -> list of strings or tables", "none",
             "a claim family: one claim per combination of values (the cross product); "
             "``{name}`` / ``{name.field}`` in any string, the id included, is filled "
             "(:func:`cosim.run.claims.expand_families`)"),
    "margin": ("a number in (0, 1)", "none (required by equal)", "typical less / greater / "
               "equal: the smallest effect the claim calls material, as a fraction of B's "
               "median; an undecided less / greater claim whose median difference's CI lies "
               "within it reads \"no effect\"; equal: the band the difference is claimed "
               "within"),
}
_CLAIM_KEYS = set(CLAIM_KEYS)
_ENSEMBLE_KEYS = set(ENSEMBLE_KEYS)
ROUNDING_RELATIVE = 1e-12  # relative change of each [ensemble].rounding_perturb parameter
CONFIDENCE = 0.95
N_RESAMPLES = 9999
BOOTSTRAP_SEED = 12345


class ClaimsError(ValueError):
    """Claims data that cannot be used (the message names the file, key and value)."""


@dataclass
class Ensemble:
    """How an entry's runs are varied (see :mod:`cosim.reproduce.entry`)."""

    seed_key: str | None = None
    report_seeds: list[int] = field(default_factory=lambda: list(range(1, 21)))
    calibration_seeds: list[int] = field(default_factory=list)
    perturb: list[str] = field(default_factory=list)
    perturb_seed: int = 0
    rounding_perturb: list[str] = field(default_factory=list)
    rounding_perturb_second: list[str] = field(default_factory=list)
    rounding_reference_path: bool = True

    def rounding_paths(self) -> tuple[int, ...]:
        """The perturbed floating-point paths of a member: 1 (``rounding_perturb``, with the
        numpy reference path unless ``rounding_reference_path`` is false) and, where
        ``rounding_perturb_second`` names parameters, 2."""
        return (1, 2) if self.rounding_perturb_second else (1,)

    def rounding_keys(self, path: int) -> list[str]:
        """The parameters scaled by 1 + 1e-12 on perturbed path ``path``."""
        return self.rounding_perturb if path == 1 else self.rounding_perturb_second
    repeats: int | None = None  # members of a "repeat" claim (None: no such claim allowed)
    members: int | None = None  # K a published page needs (None: 20, or every report seed)

    def declared_k(self) -> int:
        """K the entry's page is published from (``members``, else min(20, report seeds))."""
        return self.members if self.members is not None else min(20, len(self.report_seeds))


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
    for key in ("perturb", "rounding_perturb", "rounding_perturb_second"):
        value = data.get(key, [])
        if not (isinstance(value, list) and all(isinstance(v, str) for v in value)):
            raise ClaimsError(f"{where}: [ensemble] {key} = {value!r}: expected a list of "
                              "strings")
    try:
        parse_perturb(data.get("perturb", []))
    except ValueError as err:
        raise ClaimsError(f"{where}: [ensemble] perturb: {err}") from err
    ens.perturb = list(data.get("perturb", []))
    for name in ("rounding_perturb", "rounding_perturb_second"):
        for key in data.get(name, []):
            if "." not in key:
                raise ClaimsError(f"{where}: [ensemble] {name}: {key!r} is not "
                                  "FMU.PARAMETER")
    ens.rounding_perturb = list(data.get("rounding_perturb", []))
    ens.rounding_perturb_second = list(data.get("rounding_perturb_second", []))
    shared = sorted(set(ens.rounding_perturb) & set(ens.rounding_perturb_second))
    if shared:
        raise ClaimsError(f"{where}: [ensemble] rounding_perturb_second shares {shared} with "
                          "rounding_perturb: the second path must perturb other parameters")
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
    if "members" in data:
        k = data["members"]
        if (isinstance(k, bool) or not isinstance(k, int) or not
                1 <= k <= len(ens.report_seeds)):
            raise ClaimsError(f"{where}: [ensemble] members = {k!r}: expected an integer in "
                              f"[1, {len(ens.report_seeds)}] (K of a published page, at most "
                              "the report seeds)")
        ens.members = k
    return ens


class _Fields:
    """A family value that is a table: its fields as attributes (``{rival.run}``)."""

    def __init__(self, fields: dict[str, Any]) -> None:
        self.__dict__.update(fields)


_FAMILY_PASSES = 3  # a family value may itself name placeholders, this deep


def _fill(at: str, key: str, value: Any, names: dict[str, Any]) -> Any:
    """``value`` with the placeholders ``{name}`` / ``{name.field}`` of ``names`` filled."""
    if isinstance(value, list):
        return [_fill(at, key, v, names) for v in value]
    if isinstance(value, dict):
        return {_fill(at, key, k, names): _fill(at, key, v, names) for k, v in value.items()}
    if not isinstance(value, str):
        return value
    pattern = re.compile(r"\{(" + "|".join(map(re.escape, names)) + r")[.}]")
    for _ in range(_FAMILY_PASSES):
        if not pattern.search(value):
            return value
        try:
            value = value.format_map(names)
        except (KeyError, AttributeError, IndexError, ValueError) as err:
            raise ClaimsError(f"{at}: {key} = {value!r}: {type(err).__name__} {err} (the "
                              f"family's placeholders: {sorted(names)})") from None
    return value


def expand_families(where: str, claims: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The ``[[claims]]`` with each family expanded, in order.

    A claim with ``each`` (a table: placeholder -> list of values) stands for one claim per
    combination of values (the cross product; the first placeholder varies slowest). Every
    string of the claim (its id included) is formatted with the combination: ``{name}`` is a
    string value, ``{name.field}`` a field of a table value; a value may itself name the other
    placeholders (``paper = "{metric.paper}"`` with ``paper = "{rival.max_paper}"`` in a
    metric's table)."""
    out: list[dict[str, Any]] = []
    for i, claim in enumerate(claims):
        each = claim.get("each")
        if each is None:
            out.append(claim)
            continue
        at = f"{where}: [[claims]] #{i + 1} ({claim.get('id')!r})"
        if not (isinstance(each, dict) and each and all(
                isinstance(v, list) and v and all(isinstance(x, (str, dict)) for x in v)
                for v in each.values())):
            raise ClaimsError(f"{at}: each = {each!r}: expected a table placeholder -> "
                              "non-empty list of strings or tables")
        bad = [n for n in each if not re.fullmatch(r"[a-z_][a-z0-9_]*", n)]
        if bad:
            raise ClaimsError(f"{at}: each: placeholder name(s) {bad}: expected [a-z_][a-z0-9_]*")
        body = {k: v for k, v in claim.items() if k != "each"}
        for combo in itertools.product(*each.values()):
            names = {n: _Fields(v) if isinstance(v, dict) else v
                     for n, v in zip(each, combo, strict=True)}
            out.append({k: _fill(at, k, v, names) for k, v in body.items()})
    return out


@dataclass(frozen=True, kw_only=True)
class Claim:
    """A ``[[claims]]`` table, checked, with its defaults filled (its keys:
    :data:`CLAIM_KEYS`)."""

    id: str
    text: str
    metric: str  # the summary key tested
    kind: str  # one of CLAIM_KINDS
    runs: list[str]  # two for less / greater / equal, one otherwise
    threshold: float | None = None  # below / above, in the metric's unit
    band: list[float] | None = None  # inside: the TOML key "range", [low, high]
    quantifier: str = "typical"  # one of QUANTIFIERS (the kind's default where not given)
    share: float | None = None  # quantifier "share": the fraction of the runs
    transform: str | None = None  # "abs": the metric's absolute value per member
    ensemble: str = "disturbance"  # one of ENSEMBLES
    origin: str = "paper"  # one of ORIGINS
    source: str = ""  # where the paper makes it
    paper: str = ""  # the paper's value(s), as text
    margin: float | None = None  # typical less / greater / equal: the material effect, of
    # B's median

    @classmethod
    def from_table(cls, table: dict[str, Any]) -> Claim:
        """The claim of a (checked) ``[[claims]]`` table."""
        given = {k: v for k, v in table.items() if k not in ("range", "quantifier", "each")}
        return cls(**given, band=table.get("range"),
                   quantifier=table.get("quantifier", default_quantifier(table["kind"])))

    def bound(self) -> float | list[float] | None:
        """The threshold (below / above) or the band (inside) the claim tests against."""
        return self.threshold if self.threshold is not None else self.band


def check_claims(where: str, claims: list[dict[str, Any]], run_names: list[str],
                 ens: Ensemble) -> list[Claim]:
    """The ``[[claims]]`` tables, families expanded (:func:`expand_families`), checked
    against the entry's run names and ensemble."""
    claims = expand_families(where, claims)
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
        need = 2 if kind in PAIRED_KINDS else 1
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
        quantifier = claim.get("quantifier", default_quantifier(kind))
        if quantifier not in QUANTIFIERS:
            raise ClaimsError(f"{at}: quantifier = {quantifier!r} (known: {QUANTIFIERS})")
        share = claim.get("share")
        if (quantifier == "share") != (share is not None):
            raise ClaimsError(f"{at}: share = {share!r}: given with quantifier 'share', and "
                              "only then")
        if share is not None and (isinstance(share, bool) or not isinstance(share, (int, float))
                                  or not 0.0 < share < 1.0):
            raise ClaimsError(f"{at}: share = {share!r}: a fraction in (0, 1)")
        if claim.get("transform", "abs") != "abs":
            raise ClaimsError(f"{at}: transform = {claim['transform']!r} (known: 'abs', the "
                              "metric's absolute value per member)")
        margin = claim.get("margin")
        if margin is not None and (
                kind not in PAIRED_KINDS or quantifier != "typical"
                or isinstance(margin, bool) or not isinstance(margin, (int, float))
                or not 0.0 < margin < 1.0):
            raise ClaimsError(f"{at}: margin = {margin!r}: a fraction in (0, 1) of B's median, "
                              "for a typical less / greater / equal claim only")
        if kind == "equal" and (margin is None or quantifier != "typical"):
            raise ClaimsError(f"{at}: kind 'equal' needs a margin (the band +-margin x |median "
                              f"of B| the difference is claimed within) and quantifier "
                              f"'typical'; margin = {margin!r}, quantifier = {quantifier!r}")
        if claim.get("origin", "paper") not in ORIGINS:
            raise ClaimsError(f"{at}: origin = {claim['origin']!r} (known: {ORIGINS})")
    return [Claim.from_table(claim) for claim in claims]


def variant_runs(claim: Claim, variant: Any) -> list[str] | None:
    """The claim's runs under ``variant`` (a :class:`cosim.reproduce.parts.Variant`; None: it
    replaces none of them)."""
    rep = variant.replace
    if not any(r in rep for r in claim.runs):
        return None
    return [rep.get(r, r) for r in claim.runs]


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


def default_quantifier(kind: str) -> str:
    """``every`` for a bound on one run's metric, ``typical`` for a comparison of two runs."""
    return "every" if kind in ("below", "above", "inside") else "typical"


ALPHA = 1.0 - CONFIDENCE  # false discovery rate of a paper's claims, and two-sided level


def _sign_p(x: np.ndarray, q: float, alternative: str) -> float:
    """One-sided sign-test p-value of "the median of x is {alternative} than q"."""
    from scipy.stats import quantile_test

    return float(quantile_test(x, q=q, p=0.5, alternative=alternative).pvalue)


def _binom_p(k: int, n: int, p: float, alternative: str) -> float:
    from scipy.stats import binomtest

    return float(binomtest(k, n, p, alternative=alternative).pvalue)


def _median_ci(x: np.ndarray) -> tuple[float, float]:
    """The exact distribution-free CI of the median (order statistics, the sign test's dual),
    NaN where K is too small for one."""
    from scipy.stats import quantile_test

    ci = quantile_test(x, q=float(np.median(x)), p=0.5).confidence_interval(CONFIDENCE)
    lo, hi = float(ci.low), float(ci.high)
    return (lo, hi) if math.isfinite(lo) and math.isfinite(hi) else (math.nan, math.nan)


def _k_needed(decides: Any) -> int:
    """The smallest K at which ``decides(K)`` (the best outcome decides) is true."""
    k = 1
    while not decides(k) and k < 10_000:
        k += 1
    return k


def verdict(claim: Claim, a: np.ndarray, b: np.ndarray | None = None) -> dict[str, Any]:
    """Evaluate one claim on its members: ``a`` (runs[0]) and, for less/greater, ``b``
    (runs[1]) paired by index. Returns the median and its exact 95 % CI of the tested
    quantity, k of K on the claimed side, the worst member, the quantifier, the p-value that
    enters the multiplicity adjustment (None for ``every``) and the verdict (module text)."""
    kind = claim.kind
    quantifier = claim.quantifier
    a = np.asarray(a, dtype=float)
    if kind in PAIRED_KINDS:
        assert b is not None
        x = a - np.asarray(b, dtype=float)  # paired difference
        lo_edge = hi_edge = 0.0
        if kind == "equal":  # the band +-margin x |median of B|
            hi_edge = float(claim.margin) * abs(float(np.median(b))) if np.size(b) else math.nan
            lo_edge = -hi_edge
    elif kind in ("below", "above"):
        x = a
        lo_edge = hi_edge = float(claim.threshold)  # type: ignore[arg-type]
    else:
        x = a
        lo_edge, hi_edge = (float(v) for v in claim.band or [])
    if kind in ("less", "below"):
        good = x < lo_edge
    elif kind in ("greater", "above"):
        good = x > lo_edge
    else:
        good = (x >= lo_edge) & (x <= hi_edge)
    out: dict[str, Any] = {"quantifier": quantifier, "k": int(np.sum(good)), "K": int(x.size),
                           "median": math.nan, "ci_low": math.nan, "ci_high": math.nan,
                           "worst": math.nan, "share_low": math.nan, "p_value": None,
                           "note": ""}
    if kind in PAIRED_KINDS:
        out.update(a_median=float(np.median(a)) if a.size else math.nan,
                   b_median=float(np.median(b)) if np.size(b) else math.nan)
    if x.size == 0 or np.isnan(x).any():
        out.update(note="metric missing", verdict="inconclusive")
        return out
    out["median"] = float(np.median(x))
    out["worst"] = float(_worst(kind, x, lo_edge, hi_edge))
    if np.all(x == x[0]):  # a deterministic result: its value decides
        out.update(ci_low=float(x[0]), ci_high=float(x[0]), p_value=0.0,
                   note="all equal" if x.size > 1 else "one run",
                   verdict="holds" if good[0] else "fails")
        if quantifier == "every":
            out["p_value"] = None
        return out
    out["ci_low"], out["ci_high"] = _median_ci(x)
    n, k = x.size, out["k"]
    half = ALPHA / 2.0
    if quantifier == "every":
        from scipy.stats import binomtest

        out["share_low"] = float(binomtest(k, n, 0.5, alternative="greater")
                                 .proportion_ci(CONFIDENCE).low)
        out["verdict"] = "holds" if k == n else "fails"
        return out
    if quantifier == "share":
        p = float(claim.share)  # type: ignore[arg-type]
        p_hold, p_fail = _binom_p(k, n, p, "greater"), _binom_p(k, n, p, "less")
        can = (_binom_p(n, n, p, "greater") < half) or (_binom_p(0, n, p, "less") < half)
        need = _k_needed(lambda m: _binom_p(m, m, p, "greater") < half
                         and _binom_p(0, m, p, "less") < half)
    else:
        if kind in ("less", "below"):
            p_hold, p_fail = _sign_p(x, lo_edge, "less"), _sign_p(x, lo_edge, "greater")
        elif kind in ("greater", "above"):
            p_hold, p_fail = _sign_p(x, lo_edge, "greater"), _sign_p(x, lo_edge, "less")
        else:  # inside / equal: both edges (intersection-union); outside: either
            p_hold = max(_sign_p(x, lo_edge, "greater"), _sign_p(x, hi_edge, "less"))
            p_fail = min(_sign_p(x, lo_edge, "less"), _sign_p(x, hi_edge, "greater"))
        can = 0.5 ** n < half
        need = _k_needed(lambda m: 0.5 ** m < half)
    out["p_value"] = min(1.0, 2.0 * min(p_hold, p_fail))
    if not can or n < need:
        out.update(verdict="insufficient", note=f"K >= {need} needed")
        return out
    out["verdict"] = "holds" if p_hold < half else "fails" if p_fail < half else "inconclusive"
    if kind == "equal":
        out["note"] = f"band +-{claim.margin:.0%} of B's median = +-{number(hi_edge)}"
    if out["verdict"] == "inconclusive" and claim.margin is not None and kind != "equal":
        bound = float(claim.margin) * abs(out["b_median"])
        if -bound < out["ci_low"] and out["ci_high"] < bound:
            out.update(verdict="no effect", note=f"the median difference's CI is within "
                                                 f"+-{claim.margin:.0%} of B's median")
    return out


def _worst(kind: str, x: np.ndarray, lo: float, hi: float) -> float:
    """The member furthest toward (or past) the wrong side of the claim."""
    if kind in ("less", "below"):
        return float(np.max(x))
    if kind in ("greater", "above"):
        return float(np.min(x))
    return float(x[np.argmax(np.maximum(lo - x, x - hi))])


def adjust(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The rows of one family with ``adjusted_p`` (Benjamini-Hochberg over the rows' p-values,
    ``scipy.stats.false_discovery_control``) and ``adjusted`` (the verdict, a decision kept
    only where the adjusted p-value is below :data:`ALPHA`; rows without a p-value keep
    theirs)."""
    from scipy.stats import false_discovery_control

    tested = [i for i, r in enumerate(rows) if r.get("p_value") is not None]
    adjusted = (false_discovery_control([rows[i]["p_value"] for i in tested], method="bh")
                if tested else [])
    out = [dict(r, adjusted_p=None, adjusted=r["verdict"]) for r in rows]
    for i, q in zip(tested, adjusted, strict=True):
        out[i]["adjusted_p"] = float(q)
        if out[i]["verdict"] in ("holds", "fails") and not q < ALPHA:
            out[i]["adjusted"] = "inconclusive"
    return out


def with_rounding(main: dict[str, Any], perturbed: list[dict[str, Any]] | None
                  ) -> dict[str, Any]:
    """``main`` with ``rounding_verdict`` (each perturbed floating-point path's verdict, in
    path order, joined by " / "), ``rounding_robust`` and the final ``verdict``
    (``rounding-sensitive`` when any perturbed path's verdict differs)."""
    out = dict(main, main_verdict=main["verdict"])
    if not perturbed:
        out.update(rounding_verdict=None, rounding_robust=None)
        return out
    same = all(p["verdict"] == main["verdict"] for p in perturbed)
    out.update(rounding_verdict=" / ".join(p["verdict"] for p in perturbed),
               rounding_robust=same)
    if not same:
        out["verdict"] = "rounding-sensitive"
    return out


SIGNIFICANT = 3  # significant digits a fixed notation gives the smallest non-zero magnitude
MAX_DECIMALS = 9  # the most decimals a fixed notation shows (below: zero)


def _finite(values: Iterable[Any]) -> list[float]:
    """The finite numbers (not booleans) among ``values``."""
    return [float(v) for v in values if isinstance(v, numbers.Real) and not isinstance(v, bool)
            and math.isfinite(v)]


def decimals_for(values: Iterable[Any], significant: int = SIGNIFICANT) -> int:
    """The decimals of one fixed notation for ``values`` (a table's column, or one claim's
    median, CI and worst member): none when every finite value is a whole number, else enough
    for ``significant`` digits of the smallest non-zero magnitude, at most
    :data:`MAX_DECIMALS`. Non-numbers are left out."""
    finite = _finite(values)
    nonzero = [abs(v) for v in finite if v != 0.0]
    if not nonzero or all(v.is_integer() for v in finite):
        return 0
    return min(MAX_DECIMALS,
               max(0, significant - 1 - decimal_exponent(min(nonzero), significant)))


def fixed(value: float, decimals: int) -> str:
    """``value`` in fixed notation with ``decimals`` decimals (31130, 0.000152; never
    3.113e+04): ``-`` for NaN, a zero without its sign."""
    if math.isnan(value):
        return "-"
    if math.isinf(value):
        return "inf" if value > 0 else "-inf"
    text = f"{value:.{decimals}f}"
    return text.lstrip("-") if float(text) == 0.0 else text


def number(value: float) -> str:
    """One number alone in fixed notation (:func:`fixed` at :func:`decimals_for` of it)."""
    return fixed(value, decimals_for([value]))


def ours_text(row: dict[str, Any]) -> str:
    """``median [low, high]`` of the tested quantity in one fixed notation (:func:`fixed`;
    ``-`` where unknown); for a universal claim the worst member too."""
    worst = row.get("worst", math.nan) if row.get("quantifier") == "every" else None
    shown = [row["median"], row["ci_low"], row["ci_high"], worst]
    decimals = decimals_for(shown)

    def f(v: float | None) -> str:
        return "-" if v is None else fixed(float(v), decimals)
    text = f"{f(row['median'])} [{f(row['ci_low'])}, {f(row['ci_high'])}]"
    if worst is not None:
        text += f", worst {f(worst)}"
    b = row.get("b_median")
    if row.get("kind") in PAIRED_KINDS and b and math.isfinite(b) and not math.isnan(
            row["median"]):  # the effect's size: "no effect" and "undecided" look apart
        share = 100.0 * row["median"] / abs(b)
        text += f" ({'+' if share > 0 else ''}{fixed(share, decimals_for([share], 2))} % of B)"
    return f"{text} ({row['note']})" if row.get("note") else text
