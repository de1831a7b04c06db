"""The ``[[claims]]`` of a reproduction entry as data: their keys, claim families expanded,
each table checked against the entry's runs and ensemble (schema:
:mod:`cosim.reproduce.entry`; their statistics and verdicts: :mod:`cosim.reproduce.stats`)."""

from __future__ import annotations

import itertools
import re
from dataclasses import dataclass
from typing import Any

from cosim.reproduce.ensemble import ENSEMBLES, REQUIRED, ClaimsError, Ensemble

CLAIM_KINDS = ("less", "greater", "equal", "below", "above", "inside")
PAIRED_KINDS = ("less", "greater", "equal")  # comparing two runs, paired by member
QUANTIFIERS = ("every", "share", "typical")
ORIGINS = ("paper", "ours", "sanity")  # the paper's statement, ours, a check of the setup
# The keys of the [[claims]] tables: key -> (type, default, meaning); the schema page
# (docs/reproduce_schema.md) is written from them.
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
                   "(:mod:`cosim.reproduce.stats`)"),
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
             "(:func:`cosim.reproduce.claims.expand_families`)"),
    "margin": ("a number in (0, 1)", "none (required by equal)", "typical less / greater / "
               "equal: the smallest effect the claim calls material, as a fraction of B's "
               "median; an undecided less / greater claim whose median difference's CI lies "
               "within it reads \"no effect\"; equal: the band the difference is claimed "
               "within"),
}
_CLAIM_KEYS = set(CLAIM_KEYS)


def default_quantifier(kind: str) -> str:
    """``every`` for a bound on one run's metric, ``typical`` for a comparison of two runs."""
    return "every" if kind in ("below", "above", "inside") else "typical"


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
