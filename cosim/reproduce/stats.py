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

import functools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from cosim.reproduce.claims import PAIRED_KINDS, Claim
from cosim.reproduce.numbers import number

CONFIDENCE = 0.95
N_RESAMPLES = 9999
BOOTSTRAP_SEED = 12345


@dataclass(frozen=True, kw_only=True)
class Verdict:
    """One claim tested on its members (:func:`verdict`), in the unit of its metric."""

    quantifier: str  # one of cosim.reproduce.claims.QUANTIFIERS
    k: int  # members on the claimed side
    K: int  # members
    median: float = math.nan  # of the tested quantity (A - B for a paired claim)
    ci_low: float = math.nan  # the median's exact 95 % CI (order statistics)
    ci_high: float = math.nan
    worst: float = math.nan  # the member furthest toward the wrong side
    share_low: float = math.nan  # every: Clopper-Pearson lower bound of the share of runs
    p_value: float | None = None  # two-sided, enters the multiplicity adjustment (not every)
    note: str = ""
    a_median: float = math.nan  # paired claims: the median of runs[0]'s metric
    b_median: float = math.nan  # paired claims: the median of runs[1]'s metric
    verdict: str = "inconclusive"  # holds, fails, inconclusive, no effect or insufficient


@dataclass(frozen=True)
class Rounded:
    """A claim's verdict on the main floating-point path and on each perturbed one."""

    main: Verdict
    perturbed: tuple[Verdict, ...] = ()  # in path order; none: no perturbed rerun
    # per perturbed path: whether it changed a value the claims read in this claim's members
    # (False: the rerun gave each of them bit for bit again, so it tested nothing); none
    # given: every path did
    changed: tuple[bool, ...] = ()

    def __post_init__(self) -> None:
        if not self.changed:
            object.__setattr__(self, "changed", (True,) * len(self.perturbed))
        elif len(self.changed) != len(self.perturbed):
            raise ValueError(f"{len(self.changed)} changed flags for {len(self.perturbed)} "
                             "perturbed paths")

    def _tested(self) -> tuple[Verdict, ...]:
        """The perturbed paths' verdicts where the path changed a value (:attr:`changed`)."""
        return tuple(p for p, c in zip(self.perturbed, self.changed, strict=True) if c)

    @property
    def rounding_tested(self) -> bool | None:
        """Whether a perturbed path changed a value the claims read in this claim's members
        (None: no rerun; False: every rerun repeated the main path's values, a test of
        nothing)."""
        if not self.perturbed:
            return None
        return bool(self._tested())

    @property
    def rounding_robust(self) -> bool | None:
        """Whether every perturbed path that changed a value gives the main path's verdict
        (None: no rerun, or none changed a value: :attr:`rounding_tested`)."""
        tested = self._tested()
        if not tested:
            return None
        return all(p.verdict == self.main.verdict for p in tested)

    @property
    def rounding_verdict(self) -> str | None:
        """Each perturbed path's verdict, in path order, joined by " / " (None: no rerun)."""
        return " / ".join(p.verdict for p in self.perturbed) if self.perturbed else None

    @property
    def verdict(self) -> str:
        """The main path's verdict, or ``rounding-sensitive`` where a perturbed path's
        differs."""
        return "rounding-sensitive" if self.rounding_robust is False else self.main.verdict


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


ALPHA = 1.0 - CONFIDENCE  # false discovery rate of a paper's claims, and two-sided level


def _sign_p(x: np.ndarray, q: float, alternative: str) -> float:
    """One-sided sign-test p-value of "the median of x is {alternative} than q"."""
    from scipy.stats import quantile_test

    return float(quantile_test(x, q=q, p=0.5, alternative=alternative).pvalue)


def _binom_p(k: int, n: int, p: float, alternative: str) -> float:
    from scipy.stats import binomtest

    return float(binomtest(k, n, p, alternative=alternative).pvalue)


@functools.cache
def _median_ci_ranks(n: int) -> tuple[int, int] | None:
    """The 0-based ranks, in the sorted sample, of the ends of the exact 95 % CI of the median
    of n values (``scipy.stats.quantile_test``'s interval, whose order statistics depend on n
    alone: read off the sample 0, 1, ..., n - 1, once per n), None where n is too small."""
    from scipy.stats import quantile_test

    ci = quantile_test(np.arange(n, dtype=float), q=(n - 1) / 2.0, p=0.5
                       ).confidence_interval(CONFIDENCE)
    lo, hi = float(ci.low), float(ci.high)
    return (int(lo), int(hi)) if math.isfinite(lo) and math.isfinite(hi) else None


def _median_ci(x: np.ndarray) -> tuple[float, float]:
    """The exact distribution-free CI of the median (order statistics, the sign test's dual:
    the sorted members at :func:`_median_ci_ranks`), NaN where K is too small for one."""
    ranks = _median_ci_ranks(int(np.size(x)))
    if ranks is None:
        return math.nan, math.nan
    ordered = np.sort(np.asarray(x, dtype=float))
    return float(ordered[ranks[0]]), float(ordered[ranks[1]])


def _k_needed(decides: Callable[[int], bool]) -> int:
    """The smallest K at which ``decides(K)`` (the best outcome decides) is true."""
    k = 1
    while not decides(k) and k < 10_000:
        k += 1
    return k


def verdict(claim: Claim, a: np.ndarray, b: np.ndarray | None = None) -> Verdict:
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
    out: dict[str, object] = {"quantifier": quantifier, "k": int(np.sum(good)), "K": int(x.size),
                           "median": math.nan, "ci_low": math.nan, "ci_high": math.nan,
                           "worst": math.nan, "share_low": math.nan, "p_value": None,
                           "note": ""}
    if kind in PAIRED_KINDS:
        out.update(a_median=float(np.median(a)) if a.size else math.nan,
                   b_median=float(np.median(b)) if np.size(b) else math.nan)
    if x.size == 0 or np.isnan(x).any():
        out.update(note="metric missing", verdict="inconclusive")
        return Verdict(**out)  # type: ignore[arg-type]
    out["median"] = float(np.median(x))
    out["worst"] = float(_worst(kind, x, lo_edge, hi_edge))
    if np.all(x == x[0]):  # a deterministic result: its value decides
        out.update(ci_low=float(x[0]), ci_high=float(x[0]), p_value=0.0,
                   note="all equal" if x.size > 1 else "one run",
                   verdict="holds" if good[0] else "fails")
        if quantifier == "every":
            out["p_value"] = None
        return Verdict(**out)  # type: ignore[arg-type]
    out["ci_low"], out["ci_high"] = _median_ci(x)
    n, k = x.size, out["k"]
    half = ALPHA / 2.0
    if quantifier == "every":
        from scipy.stats import binomtest

        out["share_low"] = float(binomtest(k, n, 0.5, alternative="greater")
                                 .proportion_ci(CONFIDENCE).low)
        out["verdict"] = "holds" if k == n else "fails"
        return Verdict(**out)  # type: ignore[arg-type]
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
        return Verdict(**out)  # type: ignore[arg-type]
    out["verdict"] = "holds" if p_hold < half else "fails" if p_fail < half else "inconclusive"
    if kind == "equal":
        out["note"] = f"band +-{claim.margin:.0%} of B's median = +-{number(hi_edge)}"
    if out["verdict"] == "inconclusive" and claim.margin is not None and kind != "equal":
        bound = float(claim.margin) * abs(out["b_median"])
        if -bound < out["ci_low"] and out["ci_high"] < bound:
            out.update(verdict="no effect", note=f"the median difference's CI is within "
                                                 f"+-{claim.margin:.0%} of B's median")
    return Verdict(**out)  # type: ignore[arg-type]


def _worst(kind: str, x: np.ndarray, lo: float, hi: float) -> float:
    """The member furthest toward (or past) the wrong side of the claim."""
    if kind in ("less", "below"):
        return float(np.max(x))
    if kind in ("greater", "above"):
        return float(np.min(x))
    return float(x[np.argmax(np.maximum(lo - x, x - hi))])


def adjust(p_values: Sequence[float | None], verdicts: Sequence[str]
           ) -> list[tuple[float | None, str]]:
    """(adjusted p-value, adjusted verdict) of each claim of one family: Benjamini-Hochberg
    over the claims' p-values (``scipy.stats.false_discovery_control``), a decision kept only
    where the adjusted p-value is below :data:`ALPHA`; a claim without a p-value keeps its
    verdict."""
    from scipy.stats import false_discovery_control

    tested = [i for i, p in enumerate(p_values) if p is not None]
    adjusted = (false_discovery_control([p_values[i] for i in tested], method="bh")
                if tested else [])
    out: list[tuple[float | None, str]] = [(None, v) for v in verdicts]
    for i, q in zip(tested, adjusted, strict=True):
        keep = verdicts[i] not in ("holds", "fails") or q < ALPHA
        out[i] = (float(q), verdicts[i] if keep else "inconclusive")
    return out


def with_rounding(main: Verdict, perturbed: Sequence[Verdict] | None,
                  changed: Sequence[bool] = ()) -> Rounded:
    """``main`` beside each perturbed floating-point path's verdict and whether that path
    changed a value the claims read (:class:`Rounded`; ``changed`` empty: every path did)."""
    return Rounded(main, tuple(perturbed or ()), tuple(changed))
