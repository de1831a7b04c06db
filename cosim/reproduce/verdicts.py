"""An entry's claims evaluated on the record of their members: one row per claim (the
statistics of :mod:`cosim.reproduce.stats`, adjusted for multiplicity), ``claims.csv`` /
``claims.md`` (and ``variants.*``), the ensemble figures, and the verdicts' sentences of a
paper's page."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from cosim.reproduce.claims import ORIGINS, PAIRED_KINDS, Claim
from cosim.reproduce.entry import Entry
from cosim.reproduce.members import claim_cases, host_text, members, simulate_claims
from cosim.reproduce.numbers import decimals_for, fixed
from cosim.reproduce.record import MemberKey, Record, Summary, series_name
from cosim.reproduce.series import run_scenarios
from cosim.reproduce.stats import ALPHA, Rounded, Verdict, adjust, verdict, with_rounding
from cosim.reproduce.tables import md_row, summary_value
from cosim.run.figures import draw_ensemble_figure


@dataclass(frozen=True, kw_only=True)
class ClaimRow:
    """One claim evaluated on its members: the claim, the runs it compared (a variant's in
    place of those it replaces), its verdicts on every floating-point path and the verdict
    after the multiplicity adjustment."""

    claim: Claim
    runs: list[str]
    result: Rounded
    variant: str | None = None  # the [[variants]] entry it ran under (None: as written)
    adjusted_p: float | None = None  # Benjamini-Hochberg over the family (None: not tested)
    adjusted: str = ""  # the verdict as read, after the adjustment

    @property
    def main(self) -> Verdict:
        """The verdict on the main floating-point path."""
        return self.result.main

    @property
    def verdict(self) -> str:
        """The verdict before the adjustment (``rounding-sensitive`` where a perturbed path
        differs)."""
        return self.result.verdict

    def csv(self) -> dict[str, Any]:
        """The row of ``claims.csv`` / ``variants.csv``: the claim, then its statistics."""
        c = self.claim
        return {**({"variant": self.variant} if self.variant is not None else {}),
                "id": c.id, "source": c.source, "text": c.text, "paper": c.paper,
                "metric": c.metric, "kind": c.kind, "runs": " vs ".join(self.runs),
                "ensemble": c.ensemble, "origin": c.origin, "share": c.share,
                "threshold": c.bound(), **dataclasses.asdict(self.main),
                "main_verdict": self.main.verdict,
                "rounding_verdict": self.result.rounding_verdict,
                "rounding_tested": self.result.rounding_tested,
                "rounding_robust": self.result.rounding_robust, "verdict": self.verdict,
                "adjusted_p": self.adjusted_p, "adjusted": self.adjusted}


def _metric(summaries: dict[MemberKey, Summary | None], run: str, ens: str, n: int,
            path: int, metric: str) -> np.ndarray:
    vals = []
    for i in range(n):
        s = summaries.get((run, ens, i, path))
        v = None if s is None else summary_value(s, metric)
        ok = isinstance(v, (int, float))  # a bool (a rule met) counts as 1 / 0
        vals.append(float(v) if ok else math.nan)
    return np.array(vals)


def _same(a: Any, b: Any) -> bool:
    """Whether two recorded values are the same (bit for bit for numbers; NaN equals NaN)."""
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return True
    return type(a) is type(b) and a == b


def changed_values(summaries: dict[MemberKey, Summary | None], names: list[str], ens: str,
                   n: int, path: int, metrics: list[str]) -> bool:
    """Whether perturbed path ``path`` changed any value of ``metrics`` in a member of the
    runs ``names`` against the main path (a member that ran on one path only counts as a
    change; one missing on both does not)."""
    for name in names:
        for i in range(n):
            main, other = summaries.get((name, ens, i, 0)), summaries.get((name, ens, i, path))
            if main is None or other is None:
                if (main is None) != (other is None):
                    return True
                continue
            if not all(_same(summary_value(main, m), summary_value(other, m)) for m in metrics):
                return True
    return False


def evaluate(entry: Entry, summaries: dict[MemberKey, Summary | None], k: int,
             rounding: bool = True, variants: bool = False) -> list[ClaimRow]:
    """One row per claim (see :func:`cosim.reproduce.stats.verdict`); with ``variants`` one row
    per claim and ``[[variants]]`` entry that replaces one of its runs instead. Each
    perturbed path's verdict comes with whether that path changed a value the claims read
    (the metrics of the entry's claims that are results of the floating-point path: not the
    measured ones of ``repeat`` claims) in the claim's members (:func:`changed_values`)."""
    read = sorted({c.metric for c in entry.claims if c.ensemble != "repeat"})
    rows = []
    for var, claim, names, with_rnd, kc in claim_cases(entry, k, rounding):
        if (var != "main") != variants:
            continue
        ens = claim.ensemble
        n = len(members(entry, ens, kc))
        results = []
        paths = (0, *entry.ensemble.rounding_paths()) if with_rnd else (0,)
        for path in paths:
            a = _metric(summaries, names[0], ens, n, path, claim.metric)
            b = (_metric(summaries, names[1], ens, n, path, claim.metric)
                 if len(names) > 1 else None)
            if claim.transform == "abs":  # e.g. the stop error's size, either side
                a, b = np.abs(a), None if b is None else np.abs(b)
            results.append(verdict(claim, a, b))
        changed = [changed_values(summaries, list(names), ens, n, path, read)
                   for path in paths[1:]]
        rows.append(ClaimRow(claim=claim, runs=list(names),
                             result=with_rounding(results[0], results[1:], changed),
                             variant=var if variants else None))
    adjusted = adjust([r.main.p_value for r in rows], [r.verdict for r in rows])
    return [dataclasses.replace(r, adjusted_p=q, adjusted=v)
            for r, (q, v) in zip(rows, adjusted, strict=True)]


def variants_markdown(entry: Entry, rows: list[ClaimRow], var_rows: list[ClaimRow]) -> str:
    """Each claim's verdict as written and under every variant (a column each, the claims in
    the order of :func:`by_origin`; "=": the variant replaces none of the claim's runs), then
    what each variant replaces."""
    names = [v.name for v in entry.variants]
    got = {(r.variant, r.claim.id): r for r in var_rows}

    def cell(r: ClaimRow | None) -> str:
        if r is None:
            return "="
        return f"{_shown(r)}{rounding_flag(r)} ({r.main.k}/{r.main.K})"

    lines = [md_row(["claim", "main", *names]), "|" + " --- |" * (2 + len(names))]
    for r in by_origin(rows):
        lines.append(md_row([r.claim.id, cell(r),
                             *(cell(got.get((n, r.claim.id))) for n in names)]))
    lines += ["", "Verdict (k of K on the claimed side) of every claim with the runs of each "
              "variant in place of those it replaces; (r): rounding-sensitive; (u): the rounding "
              "rerun changed no value the claim reads (untested). The cells of "
              "all variants are one family: their p-values are adjusted together "
              f"(Benjamini-Hochberg, false discovery rate {ALPHA:g}), and a decision the "
              "adjustment does not keep reads \"inconclusive (raw: ...)\". Variants:", ""]
    for v in entry.variants:
        rep = "; ".join(f"{a} -> {b}" for a, b in v.replace.items())
        rnd = "" if v.rounding else " (no perturbed floating-point rerun)"
        if v.seeds is not None:
            rnd += f" (the first {v.seeds} report seeds at most)"
        lines.append(f"- **{v.name}**: {v.text}{rnd}. {rep}.")
    return "\n".join(lines)


VERDICTS = ("holds", "fails", "inconclusive", "no effect", "insufficient", "rounding-sensitive")


def final_verdict(r: ClaimRow) -> str:
    """A claim row's verdict as read: adjusted for multiplicity where it was, else raw."""
    return r.adjusted or r.verdict


def rounding_flag(r: ClaimRow) -> str:
    """The mark after a verdict in the short tables: " (u)" where the rounding rerun changed
    no value the claim reads, " (r)" where it changed the verdict, else nothing."""
    if r.result.rounding_tested is False:
        return " (u)"
    return " (r)" if r.result.rounding_robust is False else ""


def _shown(r: ClaimRow) -> str:
    """The adjusted verdict, with the raw one where the adjustment changed it."""
    adjusted = final_verdict(r)
    return adjusted if adjusted == r.verdict else f"{adjusted} (raw: {r.verdict})"


def rounding_text(entry: Entry, build: str = "python") -> str:
    """The perturbed floating-point paths of ``entry``'s members on ``build``, in words (the
    numpy reference path only on the Python build: every plant has a native model)."""
    ens = entry.ensemble
    first = [f"`{key}` x (1 + 1e-12)" for key in ens.rounding_perturb]
    if ens.rounding_reference_path and build == "python":
        first.append("the Python plants' numpy reference path")
    paths = [" and ".join(first)]
    if ens.rounding_perturb_second:
        paths.append(" and ".join(f"`{key}` x (1 + 1e-12)" for key in
                                  ens.rounding_perturb_second))
    return "; ".join(f"path {i}: {text}" for i, text in enumerate(paths, 1))


CLAIMS_HEADER = ("claim", "verdict", "k of K", "ours: median [95 % CI]", "paper", "source",
                 "rounding-robust")


def by_origin(rows: list[ClaimRow]) -> list[ClaimRow]:
    """The claims' rows grouped by origin (the paper's, ours, the sanity checks: the order of
    :data:`cosim.reproduce.claims.ORIGINS`), each group in the entry's order."""
    return sorted(rows, key=lambda r: ORIGINS.index(r.claim.origin))


def claims_markdown(rows: list[ClaimRow], k: int, rounding: str = "",
                    host: str = "", headings: dict[str, str] | None = None) -> str:
    """The claims table: each claim (the paper's first, then ours, then the sanity checks:
    :func:`by_origin`) with its verdict first (adjusted for multiplicity, the raw one where
    they differ), k of K, ours (after the metric's heading with its unit where ``headings``,
    metric key -> the entry's ``[[metrics]]`` heading, has it), the paper's figure and
    source; then the counts per origin and what the columns mean (``rounding``: the
    perturbed paths in words, :func:`rounding_text`; ``host``: where the repeat claims were
    measured, :func:`host_text`)."""
    headings = headings or {}
    lines = [md_row(list(CLAIMS_HEADER)), "|" + " --- |" * len(CLAIMS_HEADER)]
    for r in by_origin(rows):
        c, robust_path = r.claim, r.result.rounding_robust
        heading = headings.get(c.metric, c.metric)
        what = f"A - B, {heading}" if c.kind in PAIRED_KINDS else heading
        robust = ("n/a" if c.ensemble == "repeat" else "-" if not r.result.perturbed
                  else "untested" if not r.result.rounding_tested
                  else "yes" if robust_path else "no")
        quant = r.main.quantifier
        if quant == "share":
            quant = f"share >= {c.share}"
        lines.append(md_row([f"{c.id}: {c.text} ({quant}; {' vs '.join(r.runs)}; {c.metric}, "
                             f"{c.ensemble}; {c.origin})", _shown(r),
                             f"{r.main.k} of {r.main.K}", f"{what}: {ours_text(r)}", c.paper,
                             c.source, robust]))
    origins = dict.fromkeys(r.claim.origin for r in rows)
    counts = []
    for origin in origins:
        mine = [r for r in rows if r.claim.origin == origin]
        counts.append(f"{origin} ({len(mine)}): " + ", ".join(
            f"{v} {n}" for v in VERDICTS if (n := sum(final_verdict(r) == v
                                                      for r in mine))))
    lines += ["", f"--seeds {k}. " + "; ".join(counts) + ".", "",
              "Quantifiers: *every* holds only if every member is on the claimed side (ours "
              "gives the worst member); *typical* is the sign test on the median (exact, "
              "distribution-free; the CI is the median's exact 95 % CI, a decision that CI "
              "strictly on one side); *share >= p* the exact binomial test of k of K against "
              "p. A - B: the paired difference per member (same seed / mismatch sample); k of "
              "K: members on the claimed side. The claims of the paper are one family: the "
              "p-values of the typical and share claims are adjusted by Benjamini-Hochberg "
              f"(false discovery rate {ALPHA:g}); a decision the adjustment does not keep "
              "reads \"inconclusive (raw: ...)\". no effect: undecided, and the median "
              "difference's CI within the claim's stated margin of B's median (ours says "
              "which). insufficient: K members cannot decide "
              "whatever they show (the note says which K would). rounding-sensitive: the "
              "verdict differs on a perturbed floating-point rerun"
              + (f" ({rounding})" if rounding else "") + "; untested (rounding-robust): "
              "every rerun gave each value the claims read bit for bit again in this claim's "
              "members, so it tested nothing." + idle_paths_text(rows)]
    if any(r.claim.kind == "equal" for r in rows):
        lines[-1] += (" An equal claim (A no different from B, \"levels off\") holds when the "
                      "median difference's CI lies inside +-margin of B's median (the band "
                      "ours states), fails when the sign test puts the median outside it; k "
                      "of K: members inside the band.")
    if any(r.claim.ensemble == "repeat" for r in rows):
        lines[-1] += (" repeat: the members are repetitions of the same nominal run (K fixed "
                      "by the entry, not by --seeds), paired by repeat index; no rounding "
                      "rerun (n/a)" + (f"; {host}" if host else "") + ".")
    return "\n".join(lines)


IDLE_PATH = "changed no value a claim reads in any member"  # said of a path that tested nothing


def idle_paths(rows: list[ClaimRow]) -> list[int]:
    """The perturbed paths (1, 2, ...) that changed no value the claims read in any claim's
    members: reruns that tested nothing (:attr:`cosim.reproduce.stats.Rounded.changed`)."""
    flags = [r.result.changed for r in rows]
    n = max(map(len, flags), default=0)
    return [i + 1 for i in range(n) if not any(f[i] for f in flags if i < len(f))]


def idle_paths_text(rows: list[ClaimRow]) -> str:
    """A sentence naming :func:`idle_paths` (empty where every path changed a value)."""
    idle = idle_paths(rows)
    if not idle:
        return ""
    which = " and ".join(f"path {i}" for i in idle).capitalize()
    return f" {which} {IDLE_PATH}: it tested nothing."


def compact_table(rows: list[ClaimRow]) -> str:
    """The claims in at most 80 columns (id, k of K, adjusted verdict; (r): the rounding
    rerun changed the verdict, (u): it changed no value the claim reads), then the perturbed
    paths that changed no value at all (:func:`idle_paths`)."""
    import textwrap

    lines = [f"{'claim':<44} {'k/K':>7}  verdict", "-" * 72]
    for r in rows:
        lines.append(f"{r.claim.id[:44]:<44} {r.main.k:>3}/{r.main.K:<3}  "
                     f"{final_verdict(r)}{rounding_flag(r)}")
    if any(r.result.rounding_tested is False for r in rows):
        lines += textwrap.wrap("(u): the rounding rerun gave each value the claim reads bit "
                               "for bit again: untested." + idle_paths_text(rows), 80)
    return "\n".join(lines)


def ours_text(row: ClaimRow) -> str:
    """``median [low, high]`` of the tested quantity in one fixed notation (:func:`fixed`;
    ``-`` where unknown); for a universal claim the worst member too."""
    v = row.main
    worst = v.worst if v.quantifier == "every" else None
    shown = [v.median, v.ci_low, v.ci_high, worst]
    decimals = decimals_for(shown)

    def f(v: float | None) -> str:
        return "-" if v is None else fixed(float(v), decimals)
    text = f"{f(v.median)} [{f(v.ci_low)}, {f(v.ci_high)}]"
    if worst is not None:
        text += f", worst {f(worst)}"
    b = v.b_median
    if row.claim.kind in PAIRED_KINDS and b and math.isfinite(b) and not math.isnan(
            v.median):  # the effect's size: "no effect" and "undecided" look apart
        share = 100.0 * v.median / abs(b)
        text += f" ({'+' if share > 0 else ''}{fixed(share, decimals_for([share], 2))} % of B)"
    return f"{text} ({v.note})" if v.note else text


def write_claims(entry: Entry, record: Record, out: Path, plot_format: str = "png"
                 ) -> tuple[list[ClaimRow], str, dict[str, list[Path]]]:
    """Evaluate the entry's claims on ``record``'s members; write ``claims.csv``,
    ``claims.md`` (and ``variants.*``) and the ensemble figures (``plot_format``; a png with
    its svg beside it) to ``out``; returns the claims' rows, the markdown of claims.md below
    its title, and the paths of each ensemble figure by its figure's ``file``."""
    import pandas as pd

    k, rounding = record.seeds, record.rounding
    summaries = {job.key: record.results[ident] for ident, job in record.jobs.items()
                 if job.kind == "member"}
    rows = evaluate(entry, summaries, k, rounding)
    out.mkdir(parents=True, exist_ok=True)
    n = len(members(entry, "disturbance", k))
    drawn: dict[str, list[Path]] = {}
    scenarios = run_scenarios(entry) if n > 1 else {}  # loaded once, for every figure
    for figure in entry.figures if n > 1 else []:
        if not figure.line_kind():
            continue
        runs = [r for r in figure.runs or entry.run_names()
                if all(series_name("member", r, i) in record.series for i in range(n))]
        if runs:
            drawn[figure.file] = draw_ensemble_figure(
                figure.spec(),
                {r: [record.series[series_name("member", r, i)] for i in range(n)]
                 for r in runs},
                out / f"{Path(figure.file).stem}_ensemble.{plot_format}", scenarios,
                vector=True)
    pd.DataFrame([r.csv() for r in rows]).to_csv(out / "claims.csv", index=False)
    host = host_text([record.results[ident] for ident, job in record.jobs.items()
                      if job.kind == "member" and job.key[1] == "repeat"])
    text = claims_markdown(rows, k, rounding_text(entry, record.build) if rounding else "",
                           host, {m.key: m.heading for m in entry.metrics}) + "\n"
    if entry.variants:
        var_rows = evaluate(entry, summaries, k, rounding, variants=True)
        pd.DataFrame([r.csv() for r in var_rows]).to_csv(out / "variants.csv", index=False)
        text += ("\n#### The claims under each variant\n\n"
                 + variants_markdown(entry, rows, var_rows) + "\n")
    (out / "claims.md").write_text(f"## Claims of {entry.title}\n\n" + text)
    return rows, text, drawn


def verdict_summary(rows: list[ClaimRow], k: int) -> str:
    """The verdicts in one sentence for the top of a paper's page: the counts per origin
    (after the multiplicity adjustment)."""
    counts = []
    for origin in dict.fromkeys(r.claim.origin for r in rows):
        mine = [r for r in rows if r.claim.origin == origin]
        got = ", ".join(f"{n} {v}" for v in VERDICTS
                        if (n := sum(final_verdict(r) == v for r in mine)))
        counts.append(f"{len(mine)} {'of the paper' if origin == 'paper' else origin}: {got}")
    return (f"**Verdicts** over K = {k} seeds (Benjamini-Hochberg adjusted; table below): "
            + "; ".join(counts) + ".")


def failed_claims_markdown(rows: list[ClaimRow]) -> str:
    """The paper's claims that fail here (after the multiplicity adjustment), as a list under
    its lead sentence; empty when none fails."""
    failed = [r for r in rows if r.claim.origin == "paper"
              and final_verdict(r) == "fails"]
    if not failed:
        return ""
    return "\n".join(["Not reproduced (the paper's claims that fail here):", "",
                      *(f"- {r.claim.text} (`{r.claim.id}`)" for r in failed)])


def run_claims(entry: Entry, out: Path, k: int, workers: int | None = None,
               rounding: bool = True, scheduler: str | None = None,
               plot_format: str = "png", build: str = "python") -> list[ClaimRow]:
    """Run and evaluate the entry's claims (:func:`simulate_claims`, then
    :func:`write_claims` on that record); returns the claims' rows."""
    record = Record(entry.name, "", k, rounding, build)
    simulate_claims(entry, out, record, workers, scheduler)
    return write_claims(entry, record, out, plot_format)[0]
