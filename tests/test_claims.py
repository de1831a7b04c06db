"""Claims as data: statistics on synthetic samples with known answers, the schema's errors,
disjoint seeds, rounding-sensitive marking, and (slow) every entry's claims at small K."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest
from claim_rows import claim_row

from cosim.reproduce.claims import Claim, check_claims, expand_families
from cosim.reproduce.ensemble import ClaimsError, check_ensemble, parse_seeds
from cosim.reproduce.entry import ReproduceError, Run, Variant, entry_names, load_entry
from cosim.reproduce.stats import median_ci, with_rounding
from cosim.reproduce.stats import verdict as claim_verdict


def verdict(table: dict, a: np.ndarray, b: np.ndarray | None = None) -> dict:
    """The verdict of the claim of ``table`` (a ``[[claims]]`` table) on ``a`` and ``b``."""
    return claim_verdict(Claim.from_table(table), a, b)


LESS = {"id": "a_below_b", "text": "A below B", "metric": "m", "kind": "less",
        "runs": ["A", "B"]}
RNG = np.random.default_rng(7)
NOISE = RNG.standard_normal(20)


def test_planted_difference_holds() -> None:
    # A = B - 1 on every seed (plus the same seed noise): the paired difference is -1 exactly
    b = 5.0 + NOISE
    r = verdict(LESS, b - 1.0 + 0.01 * RNG.standard_normal(20), b)
    assert r.verdict == "holds" and r.k == 20 and r.K == 20
    assert r.ci_low <= r.median <= r.ci_high < 0.0


def test_no_difference_is_inconclusive() -> None:
    # independent N(0, 1) pairs: the median difference's CI covers 0 for this fixed sample
    a, b = RNG.standard_normal(20), RNG.standard_normal(20)
    r = verdict(LESS, a, b)
    assert r.ci_low < 0.0 < r.ci_high
    assert r.verdict == "inconclusive"


def test_reversed_difference_fails() -> None:
    b = 5.0 + NOISE
    r = verdict(LESS, b + 1.0, b)
    assert r.verdict == "fails" and r.k == 0
    assert verdict({**LESS, "kind": "greater"}, b + 1.0, b).verdict == "holds"


def test_threshold_and_range_kinds_under_each_quantifier() -> None:
    x = 0.1 + 0.01 * NOISE
    below = {**LESS, "kind": "below", "threshold": 0.2, "runs": ["A"]}
    assert verdict(below, x).verdict == "holds"
    assert verdict({**below, "kind": "above"}, x).verdict == "fails"
    inside = {**LESS, "kind": "inside", "range": [-0.5, 0.5], "runs": ["A"]}
    assert verdict(inside, x).verdict == "holds"
    assert verdict(inside, x + 1.0).verdict == "fails"
    # the median at the edge: some members outside, so "every" fails on them; the median's
    # sign test decides neither way
    straddle = 0.5 + 0.01 * NOISE
    r = verdict(inside, straddle)
    assert r.quantifier == "every" and r.verdict == "fails"
    assert r.worst == straddle.max() and r.k == int(np.sum(straddle <= 0.5))
    assert verdict({**inside, "quantifier": "typical"}, straddle).verdict == "inconclusive"


def test_a_universal_claim_is_decided_by_its_worst_member() -> None:
    """"Stops within +-50 cm": 19 of 20 inside and one at 0.70 m fails, though the median and
    its CI are well inside; 20 of 20 holds, with the share of runs it supports: the one-sided
    Clopper-Pearson bound, alpha^(1/K) for K of K."""
    from cosim.reproduce.stats import ALPHA

    inside = {**LESS, "kind": "inside", "range": [-0.5, 0.5], "runs": ["A"]}
    x = 0.1 + 0.01 * NOISE
    one_out = x.copy()
    one_out[7] = 0.70
    r = verdict(inside, one_out)
    assert r.verdict == "fails" and (r.k, r.K) == (19, 20) and r.worst == 0.70
    assert r.p_value is None  # a counterexample is not an inference
    r = verdict(inside, x)
    assert r.verdict == "holds"
    assert r.share_low == pytest.approx(ALPHA ** (1 / 20), rel=1e-9)


def test_a_typical_claim_decides_at_most_alpha_of_null_samples_and_small_k_is_insufficient(
        ) -> None:
    """The sign test's decisions, enumerated over every k of K (not sampled): under no
    difference (each sign a fair coin) the probability of any decision is at most alpha; with
    K too small to decide whatever the members show, the verdict says which K would."""
    from scipy.stats import binom

    from cosim.reproduce.stats import ALPHA

    for K in (6, 10, 20, 33):
        decided = 0.0
        for k in range(K + 1):
            x = np.where(np.arange(K) < k, -1.0, 1.0) * (1.0 + np.arange(K))
            r = verdict(LESS, x, np.zeros(K))
            assert r.k == k and r.verdict in ("holds", "fails", "inconclusive")
            if r.verdict != "inconclusive":
                decided += binom.pmf(k, K, 0.5)
        assert decided <= ALPHA
    for K in (1, 3, 5):
        x = -1.0 - np.arange(K)  # every member on the claimed side
        r = verdict(LESS, x, np.zeros(K)) if K > 1 else verdict(LESS, x, np.array([0.0]))
        if K == 1:
            assert r.verdict == "holds" and r.note == "one run"  # deterministic
        else:
            assert r.verdict == "insufficient" and r.note == "K >= 6 needed"


def test_a_share_claim_is_the_exact_binomial_test() -> None:
    """At least 80 % of runs: 20 of 20 decide it (0.8^20 < 0.025), 19 of 20 do not
    (P(X >= 19) = 0.069); 5 members can never decide (0.8^5 > 0.025): 17 would."""
    share = {**LESS, "kind": "below", "threshold": 0.0, "runs": ["A"],
             "quantifier": "share", "share": 0.8}
    x = -1.0 - np.arange(20.0)
    assert verdict(share, x).verdict == "holds"
    x[3] = 1.0
    assert verdict(share, x).verdict == "inconclusive"
    assert verdict(share, -x).verdict == "fails"  # 1 of 20
    r = verdict(share, -1.0 - np.arange(5.0))
    assert r.verdict == "insufficient" and r.note == "K >= 17 needed"


def test_multiplicity_adjustment_is_benjamini_hochberg() -> None:
    """adjust() against the definition: q_(i) = min_{j >= i} p_(j) m / j over the sorted
    p-values; a decision is kept where q < alpha; rows without a p-value keep theirs."""
    from cosim.reproduce.stats import ALPHA, adjust

    ps = [0.001, 0.04, 0.03, 0.2, 0.012]
    out = adjust([*ps, None], ["holds"] * len(ps) + ["fails"])
    order = np.argsort(ps)
    m = len(ps)
    q = np.minimum.accumulate((np.array(ps)[order] * m / np.arange(1, m + 1))[::-1])[::-1]
    want = np.empty(m)
    want[order] = q
    assert [p for p, _ in out[:m]] == pytest.approx(list(want), rel=1e-12)
    assert out[m][0] is None
    assert [v for _, v in out] == [
        "holds" if w < ALPHA else "inconclusive" for w in want] + ["fails"]


def test_degenerate_samples_give_a_stated_verdict() -> None:
    # all equal (a deterministic run): the value decides
    med, lo, hi, note = median_ci(np.full(5, 2.0))
    assert (med, lo, hi, note) == (2.0, 2.0, 2.0, "all equal")
    assert verdict(LESS, np.array([1.0]), np.array([2.0])).verdict == "holds"
    assert verdict(LESS, np.array([2.0]), np.array([2.0])).verdict == "fails"
    # NaN / missing metric and a K too small to decide
    r = verdict(LESS, np.array([1.0, np.nan, 1.0]), np.array([2.0, 2.0, 2.0]))
    assert r.verdict == "inconclusive" and r.note == "metric missing"
    r = verdict(LESS, np.array([1.0, 1.5]), np.array([2.0, 2.0]))
    assert r.verdict == "insufficient" and r.note == "K >= 6 needed"


def test_the_median_ci_is_scipys_exact_interval_for_every_k_with_ties() -> None:
    """The verdicts' CI of the median (its order statistics found once per K) against
    ``scipy.stats.quantile_test``'s interval on each sample itself: K = 1..60, continuous and
    tied samples, bit for bit, NaN where K is too small for one."""
    from scipy.stats import quantile_test

    from cosim.reproduce.stats import CONFIDENCE, _median_ci

    rng = np.random.default_rng(7)
    for k in range(1, 61):
        for x in (rng.normal(size=k), rng.integers(0, 3, size=k).astype(float)):
            ci = quantile_test(x, q=float(np.median(x)), p=0.5).confidence_interval(CONFIDENCE)
            want = ((float(ci.low), float(ci.high))
                    if np.isfinite(ci.low) and np.isfinite(ci.high) else None)
            got = _median_ci(x)
            if want is None:
                assert all(np.isnan(got)), (k, got)
            else:
                assert got == want, (k, x, got, want)


def test_rounding_sensitive_is_never_holds() -> None:
    b = 5.0 + NOISE
    main = verdict(LESS, b - 1.0, b)
    fake_perturbed = verdict(LESS, b + 1.0, b)  # a perturbed path that flips the order
    out = with_rounding(main, [fake_perturbed])
    assert main.verdict == "holds"
    assert out.verdict == "rounding-sensitive" and out.rounding_robust is False
    assert out.main.verdict == "holds" and out.rounding_verdict == "fails"
    agree = verdict(LESS, b - 1.0 + 1e-12, b)
    same = with_rounding(main, [agree])
    assert same.verdict == "holds" and same.rounding_robust is True
    # two independent paths: one agreeing by chance does not hide the other's flip
    both = with_rounding(main, [agree, fake_perturbed])
    assert both.verdict == "rounding-sensitive" and both.rounding_robust is False
    assert both.rounding_verdict == "holds / fails"
    assert with_rounding(main, [agree, agree]).verdict == "holds"
    assert with_rounding(main, None).rounding_robust is None
    # a path that changed nothing the claims read is no test: only the others count
    assert with_rounding(main, [agree, fake_perturbed], [True, False]).rounding_robust is True
    idle = with_rounding(main, [fake_perturbed], [False])
    assert idle.rounding_tested is False and idle.rounding_robust is None
    with pytest.raises(ValueError, match="1 changed flags for 2 perturbed paths"):
        with_rounding(main, [agree, agree], [True])


def test_seeds_parse_and_must_be_disjoint() -> None:
    assert parse_seeds("x", "report_seeds", "1..3, 7..8") == [1, 2, 3, 7, 8]
    with pytest.raises(ClaimsError, match="report_seeds = '3..1'"):
        parse_seeds("x", "report_seeds", "3..1")
    with pytest.raises(ClaimsError, match=r"share \[4\].*disjoint"):
        check_ensemble("e.toml", {"report_seeds": "1..5", "calibration_seeds": "4, 9"})
    ens = check_ensemble("e.toml", {"report_seeds": "1..3", "calibration_seeds": "4..6"})
    assert ens.report_seeds == [1, 2, 3] and ens.calibration_seeds == [4, 5, 6]


@pytest.mark.parametrize(("change", "message"), [
    ({"kind": "smaller"}, "kind = 'smaller'"),
    ({"runs": ["A", "C"]}, "runs: 'C' is not one of"),
    ({"runs": ["A"]}, "compares 2 run"),
    ({"id": "Bad-Id"}, "id = 'Bad-Id'"),
    ({"kind": "below", "runs": ["A"]}, "threshold = None"),
    ({"kind": "inside", "runs": ["A"], "range": [1, 0]}, "range = \\[1, 0\\]"),
    ({"ensemble": "mismatch"}, "needs \\[ensemble\\] perturb"),
    ({"colour": 1}, "unknown key"),
])
def test_claim_schema_errors_name_file_key_and_value(change: dict, message: str) -> None:
    with pytest.raises(ClaimsError, match=f"e.toml: \\[\\[claims\\]\\].*{message}"):
        check_claims("e.toml", [{**LESS, **change}], ["A", "B"], check_ensemble("e.toml", {}))


def test_a_claim_family_is_the_cross_product_of_its_placeholders() -> None:
    family = {"id": "{a}_{m.key}_below_{b.key}", "text": "{a} below {b.run} on {m.key}",
              "metric": "{m.name}", "kind": "less", "runs": ["{a}", "{b.run}"],
              "paper": "{m.paper}",
              "each": {"a": ["x", "y"],
                       "b": [{"key": "p", "run": "P", "note": "b's"}, {"key": "q", "run": "Q"}],
                       "m": [{"key": "e", "name": "err", "paper": "{b.key}/{a}"}]}}
    out = expand_families("e.toml", [LESS, family])
    assert out[0] is LESS
    assert [c["id"] for c in out[1:]] == ["x_e_below_p", "x_e_below_q", "y_e_below_p",
                                          "y_e_below_q"]  # the first placeholder slowest
    assert out[4] == {"id": "y_e_below_q", "text": "y below Q on e", "metric": "err",
                      "kind": "less", "runs": ["y", "Q"], "paper": "q/y"}  # nested: "q/y"
    claims = check_claims("e.toml", [family], ["x", "y", "P", "Q"], check_ensemble("e.toml", {}))
    assert [c.id for c in claims] == [c["id"] for c in out[1:]]
    assert claims[3] == Claim(id="y_e_below_q", text="y below Q on e", metric="err", kind="less",
                              runs=["y", "Q"], paper="q/y")


@pytest.mark.parametrize(("each", "message"), [
    ({"a": []}, "non-empty list"),
    ({"a": "x"}, "non-empty list"),
    ({"A-b": ["x"]}, "placeholder name"),
    ({"a": [{"key": "k"}]}, "AttributeError"),  # {a.name} of a table without "name"
])
def test_claim_family_errors_name_the_claim_and_field(each: dict, message: str) -> None:
    family = {**LESS, "id": "f_{a.name}", "each": each}
    with pytest.raises(ClaimsError, match=f"e.toml: \\[\\[claims\\]\\] #1.*{message}"):
        expand_families("e.toml", [family])


def test_a_family_expanding_to_a_repeated_id_is_refused() -> None:
    family = {**LESS, "id": "same", "text": "{a}", "each": {"a": ["x", "y"]}}
    with pytest.raises(ClaimsError, match="id = 'same' repeats"):
        check_claims("e.toml", [family], ["A", "B"], check_ensemble("e.toml", {}))


def test_entry_with_bad_claim_fails_on_load(tmp_path: Path) -> None:
    path = tmp_path / "bad.toml"
    path.write_text('title = "t"\n[[runs]]\nname = "A"\nscenario = "seed000_stop_pid"\n'
                    '[[claims]]\nid = "x"\ntext = "t"\nmetric = "m"\nkind = "below"\n'
                    'runs = ["A"]\nthreshold = "high"\n')
    with pytest.raises(ReproduceError, match=r"bad.toml: \[\[claims\]\] 'x': threshold = "
                                             "'high'"):
        load_entry(path)


def test_shipped_entries_claims_load() -> None:
    for name in entry_names():
        entry = load_entry(name)
        for claim in entry.claims:
            assert claim.runs[0] in entry.run_names()


CLAIMS_SMOKE_ENTRY = "seed000"  # its runs are a minute of a stopping train: the cheapest


@pytest.mark.slow
def test_an_entry_claims_get_verdicts_end_to_end(built_fmus, tmp_path: Path) -> None:
    """The whole claims path (jobs, ensemble, figures, verdicts, files) on the cheapest
    entry at K = 3. Every entry's claims got their verdicts from the code of this tree in its
    recorded K = 20 reproduction: the paper pages carry the digest of every file that changes
    a number, and ``tests/test_docs_site.py::test_generated_pages_are_current`` fails when it
    differs, so the costlier entries (each 36-117 claim jobs of whole runs at K = 3) need no
    second, smaller run here."""
    from cosim.reproduce.verdicts import run_claims

    name = CLAIMS_SMOKE_ENTRY
    entry = load_entry(name)
    rows = run_claims(entry, tmp_path, 3, workers=2)
    assert [r.claim.id for r in rows] == [c.id for c in entry.claims]
    for r in rows:  # K = 3 decides universal claims on the members, and no median
        main = r.main.verdict
        if r.main.quantifier == "every" and r.main.note != "metric missing":
            assert main == ("holds" if r.main.k == r.main.K else "fails"), r
        elif r.main.note not in ("all equal", "one run", "metric missing"):
            assert main == "insufficient" and r.main.note == "K >= 6 needed", r
    assert (tmp_path / "claims.csv").is_file() and (tmp_path / "claims.md").is_file()


def test_ensemble_figure_draws_median_and_band(tmp_path: Path) -> None:
    import pandas as pd

    from cosim.run.figures import FigureError, draw_ensemble_figure

    t = np.linspace(0.0, 10.0, 11)
    dirs = [pd.DataFrame({"time": t, "plant.v": t + i, "controller.v_ref": t})
            for i in range(4)]
    spec = {"file": "f.png", "x": "time", "y": ["plant.v"], "y_minus": "controller.v_ref"}
    draw_ensemble_figure(spec, {"A": dirs}, tmp_path / "f_ensemble.png")
    assert (tmp_path / "f_ensemble.png").stat().st_size > 0
    spec["y"] = ["plant.missing"]
    with pytest.raises(FigureError, match="recorded no 'plant.missing'"):
        draw_ensemble_figure(spec, {"A": dirs}, tmp_path / "g.png")


def test_a_margin_tells_no_effect_from_undecided() -> None:
    """With a stated margin, an undecided comparison whose median difference's exact CI lies
    within +-margin of B's median is "no effect"; a wide CI stays "inconclusive", and a
    decided one keeps its decision."""
    b = 100.0 + NOISE
    centred = NOISE - np.median(NOISE)  # a median difference of 0: the sign test undecided
    tiny = b + 0.05 * centred  # differences ~0.05: CI well inside +-1 (1 % of ~100)
    wide = b + 5.0 * centred  # differences ~5: CI beyond +-1
    claim = {**LESS, "margin": 0.01}
    small = verdict(claim, tiny, b)
    assert small.verdict == "no effect" and "1%" in small.note
    assert -1.0 < small.ci_low and small.ci_high < 1.0
    assert verdict(claim, wide, b).verdict == "inconclusive"
    assert verdict(claim, b - 3.0, b).verdict == "holds"
    assert verdict(LESS, tiny, b).verdict == "inconclusive"  # no margin, no equivalence


def test_an_equal_claim_is_the_two_one_sided_tests_of_its_band() -> None:
    """``equal`` holds when the median difference's exact CI lies inside +-margin x |median of
    B| (both one-sided sign tests decide), fails when the median is decided outside the band,
    and stays undecided when the CI straddles an edge; k counts the members inside it."""
    b = 100.0 + NOISE  # median of B about 100: a 5 % band is about +-5
    centred = NOISE - np.median(NOISE)
    claim = {**LESS, "kind": "equal", "margin": 0.05}
    inside = verdict(claim, b + 0.5 * centred, b)
    band = 0.05 * abs(float(np.median(b)))
    assert inside.verdict == "holds" and inside.k == 20
    assert -band < inside.ci_low and inside.ci_high < band
    assert "5%" in inside.note
    assert verdict(claim, b - 3.0 * band + 0.1 * centred, b).verdict == "fails"
    assert verdict(claim, b + 3.0 * band + 0.1 * centred, b).verdict == "fails"
    edge = verdict(claim, b + band + 0.5 * centred, b)  # the median on the edge: undecided
    assert edge.verdict == "inconclusive" and edge.ci_low < band < edge.ci_high
    # the same samples under "less" with the margin: the tiny difference is "no effect"
    assert verdict({**claim, "kind": "less"}, b + 0.05 * centred, b).verdict == "no effect"


@pytest.mark.parametrize("change", [{}, {"margin": 0.1, "quantifier": "every"},
                                    {"margin": 0.1, "runs": ["A"]}])
def test_an_equal_claim_needs_a_margin_a_typical_quantifier_and_two_runs(change: dict
                                                                        ) -> None:
    with pytest.raises(ClaimsError, match="equal|margin = |runs = "):
        check_claims("e.toml", [{**LESS, "kind": "equal", **change}], ["A", "B"],
                     check_ensemble("e.toml", {}))


@pytest.mark.parametrize("change", [{"margin": 1.5}, {"margin": 0.1, "kind": "below",
                                                      "runs": ["A"], "threshold": 1.0},
                                    {"margin": 0.1, "quantifier": "every"}])
def test_a_margin_is_a_fraction_on_a_typical_comparison(change: dict) -> None:
    with pytest.raises(ClaimsError, match="margin = "):
        check_claims("e.toml", [{**LESS, **change}], ["A", "B"], check_ensemble("e.toml", {}))


def test_reproduction_summary_counts_verdicts() -> None:
    from cosim.reproduce.page import claims_summary

    rows = [claim_row(id=i, verdict=v, adjusted=a) for i, v, a in (
        ("x", "holds", "holds"), ("y", "fails", "fails"), ("z", "holds", "inconclusive"))]
    lines = claims_summary({"a": rows, "b": []}).splitlines()
    assert lines[0] == ("| entry | claims | holds | fails | inconclusive | no effect | "
                        "insufficient | rounding-sensitive |")
    assert lines[2] == "| a | 3 | 1 | 1 | 1 | 0 | 0 | 0 |"  # the adjusted verdicts
    assert lines[3] == "| b | 0 | - | - | - | - | - | - |"


def test_ratio_ci_of_repeated_timings() -> None:
    """The ratio of medians of two independent repetition sets with its bootstrap CI: exact
    for constant repetitions, proportional to a scale of one side (same resamples), bracketing
    the point ratio, and without bounds under 3 repetitions."""
    from cosim.reproduce.stats import ratio_ci

    assert ratio_ci(np.full(5, 2.0), np.full(4, 1.0)) == (2.0, 2.0, 2.0)
    rng = np.random.default_rng(3)
    a, b = rng.normal(10.0, 1.0, 10), rng.normal(20.0, 2.0, 10)
    r, lo, hi = ratio_ci(a, b)
    assert lo <= r <= hi and lo < hi
    r3, lo3, hi3 = ratio_ci(3.0 * a, b)
    assert (r3, lo3, hi3) == pytest.approx((3 * r, 3 * lo, 3 * hi), rel=1e-12)
    r2, lo2, hi2 = ratio_ci(a[:2], b)
    assert r2 == pytest.approx(np.median(a[:2]) / np.median(b)) and np.isnan(lo2)

def _variant_entry() -> object:
    from types import SimpleNamespace

    return SimpleNamespace(
        claims=[Claim.from_table(c) for c in (LESS, {**LESS, "id": "c_below_b",
                                                          "runs": ["C", "B"]})],
        variants=[Variant(name="alt", replace={"A": "A2"}, seeds=4)],
        ensemble=check_ensemble("e.toml", {"seed_key": "plant.seed", "report_seeds": "1..6"}),
        runs=[Run(name=n, scenario="s") for n in ("A", "A2", "B", "C")], path="e.toml")


def test_variants_replace_runs_in_every_claim_and_get_their_own_verdicts() -> None:
    from cosim.reproduce.members import claim_jobs
    from cosim.reproduce.verdicts import evaluate

    entry = _variant_entry()
    jobs = {key for key, _sc, _ov in claim_jobs(entry, 6, rounding=False)}
    # A2 runs on the variant's 4 seeds only; the claim on C vs B is untouched by the variant
    assert {k for k in jobs if k[0] == "A2"} == {("A2", "disturbance", i, False)
                                                  for i in range(4)}
    # a variant gets the perturbed floating-point rerun like the main claims, unless it opts out
    with_rerun = {key for key, _sc, _ov in claim_jobs(entry, 6, rounding=True)}
    assert ("A2", "disturbance", 3, True) in with_rerun
    entry.variants = [dataclasses.replace(entry.variants[0], rounding=False)]
    without = {key for key, _sc, _ov in claim_jobs(entry, 6, rounding=True)}
    assert not any(k[0] == "A2" and k[3] for k in without)
    assert ("A", "disturbance", 5, True) in without
    entry = _variant_entry()
    # A2 below B on every seed, A above B: the variant flips the verdict of a_below_b only
    summaries = {}
    for run, value in (("A", 2.0), ("A2", 0.0), ("B", 1.0), ("C", 0.0)):
        for i in range(6):
            summaries[(run, "disturbance", i, False)] = {"m": value + 0.01 * i}
    main = evaluate(entry, summaries, 6, rounding=False)
    alt = evaluate(entry, summaries, 6, rounding=False, variants=True)
    assert [(r.claim.id, r.verdict) for r in main] == [("a_below_b", "fails"),
                                                       ("c_below_b", "holds")]
    assert [(r.variant, r.claim.id, r.verdict, r.main.K) for r in alt] == [
        ("alt", "a_below_b", "holds", 4)]


@pytest.mark.parametrize("variant,message", [
    ({"name": "v", "replace": {"A": "Z"}}, "replace: 'Z' is not one of"),
    ({"name": "main", "replace": {"A": "B"}}, "name = 'main'"),
    ({"name": "v", "replace": {}}, "replace = \\{\\}"),
    ({"name": "v", "replace": {"A": "B"}, "seeds": 0}, "seeds = 0"),
    ({"name": "v", "replace": {"A": "B"}, "colour": 1}, "unknown key"),
])
def test_variant_schema_errors_name_file_key_and_value(variant: dict, message: str) -> None:
    from cosim.reproduce.entry import check_variants

    with pytest.raises(ReproduceError, match=f"e.toml: \\[\\[variants\\]\\].*{message}"):
        check_variants("e.toml", [variant], ["A", "B"])


def test_panels_ensemble_figure_draws_limits(tmp_path: Path) -> None:
    import pandas as pd

    from cosim.run.figures import FigureError, draw_ensemble_figure

    t = np.linspace(0.0, 10.0, 11)
    dirs = [pd.DataFrame({"time": t, "plant.v[1]": t + i, "plant.v[2]": t - i,
                          "controller.v_ref": t}) for i in range(3)]
    spec = {"file": "f.png", "kind": "panels", "x": "time", "y": ["plant.v[1]", "plant.v[2]"],
            "y_minus": "controller.v_ref", "y_scale": 3.6, "limit_ref": "controller.v_ref"}
    draw_ensemble_figure(spec, {"A": dirs, "B": dirs}, tmp_path / "f_ensemble.png")
    assert (tmp_path / "f_ensemble.png").stat().st_size > 0
    spec["limit_ref"] = "controller.missing"
    with pytest.raises(FigureError, match="recorded no 'controller.missing'"):
        draw_ensemble_figure(spec, {"A": dirs}, tmp_path / "g.png")


def _repeat_entry(repeats: int = 4) -> object:
    from types import SimpleNamespace

    timing = {**LESS, "id": "a_faster_than_b", "metric": "t", "ensemble": "repeat"}
    return SimpleNamespace(
        claims=[Claim.from_table(c) for c in (
            timing, {**timing, "id": "c_faster_than_b", "runs": ["C", "B"]}, LESS)],
        variants=[],
        ensemble=check_ensemble("e.toml", {"seed_key": "plant.seed", "report_seeds": "1..3",
                                           "repeats": repeats}),
        runs=[Run(name="A", scenario="s", overrides={"controller.x": 1}),
              Run(name="B", scenario="s"), Run(name="C", scenario="s")],
        path="e.toml")


def test_repeat_members_are_the_nominal_run_interleaved_without_rounding() -> None:
    from cosim.reproduce.members import claim_jobs, members

    entry = _repeat_entry(4)
    # K of a repeat claim is the entry's repeats, whatever --seeds (here 2 and 3)
    assert members(entry, "repeat", 2) == members(entry, "repeat", 3) == [{}] * 4
    jobs = claim_jobs(entry, 2, rounding=True)
    rep = [(key, ov) for key, _sc, ov in jobs if key[1] == "repeat"]
    # first, by repeat index then run: A0, B0, C0, A1, ...; never a rounding rerun
    assert [key for key, _ov in rep] == [(r, "repeat", i, False)
                                         for i in range(4) for r in ("A", "B", "C")]
    assert [key for key, _sc, _ov in jobs[:len(rep)]] == [key for key, _ov in rep]
    # every repeat of a run has the same overrides: the run's own set, no seed
    assert {r: [ov for key, ov in rep if key[0] == r] for r in "ABC"} == {
        "A": [{"controller.x": 1}] * 4, "B": [{}] * 4, "C": [{}] * 4}
    # the disturbance claim keeps its seeds and its rounding rerun
    dist = {key for key, _sc, _ov in jobs if key[1] == "disturbance"}
    assert dist == {(r, "disturbance", i, rnd) for r in "AB" for i in range(2)
                    for rnd in (False, True)}


def test_repeat_verdict_over_the_repeats_pairs_by_index() -> None:
    from cosim.reproduce.verdicts import claims_markdown, evaluate

    entry = _repeat_entry(5)
    drift = np.arange(5.0)  # a load drift met by both runs of a pair
    summaries: dict = {}
    for i in range(5):
        summaries[("A", "repeat", i, False)] = {"t": 1.0 + drift[i]}
        summaries[("B", "repeat", i, False)] = {"t": 1.5 + drift[i]}
        summaries[("C", "repeat", i, False)] = {"t": 2.0 + drift[i]}
    for r in "AB":
        for i in range(2):
            for rnd in (False, True):  # the rerun one ulp off: a tested path
                summaries[(r, "disturbance", i, rnd)] = {
                    "m": (0.0 if r == "A" else 1.0) + rnd * 2.0**-52}
    rows = {r.claim.id: r for r in evaluate(entry, summaries, 2, rounding=True)}
    # the paired differences are exactly -0.5 and +0.5 on every repeat, though the drift
    # spans the samples of each run
    a = rows["a_faster_than_b"]
    assert (a.verdict, a.main.k, a.main.K, a.main.median) == ("holds", 5, 5, -0.5)
    assert a.result.rounding_robust is None and a.result.rounding_verdict is None
    c = rows["c_faster_than_b"]
    assert (c.verdict, c.main.k, c.main.K) == ("fails", 0, 5)
    assert rows["a_below_b"].main.K == 2 and rows["a_below_b"].result.rounding_robust is True
    text = claims_markdown(list(rows.values()), 2)
    line = next(x for x in text.splitlines() if x.startswith("| a_faster_than_b"))
    assert line.rstrip(" |").endswith("n/a") and "repeat index" in text


def test_a_rerun_that_changes_no_value_the_claims_read_is_untested() -> None:
    """A perturbed path that gives every value the claims read bit for bit again in a
    claim's members tested nothing: the claim reads "untested", not rounding-robust, and a
    path that changed nothing anywhere is named; the repeat claims' measured values do not
    count as a change. One ulp anywhere in the claim's members makes it a test."""
    from cosim.reproduce.verdicts import claims_markdown, compact_table, evaluate

    entry = _repeat_entry(3)
    entry.claims.append(Claim.from_table({**LESS, "id": "c_below_b", "runs": ["C", "B"]}))

    def summaries(ulp: dict[str, float]) -> dict:
        out: dict = {}
        for r in "ABC":
            for i in range(3):  # timing differs on every run, as measured times do
                out[(r, "repeat", i, False)] = {"t": 1.0 + i + 0.1 * (r == "A")}
            for i in range(2):
                for rnd in (False, True):
                    base, slope = {"A": (0.0, 0.1), "B": (1.0, 0.3), "C": (0.5, 0.2)}[r]
                    m = base + slope * i + (i == 1) * rnd * ulp.get(r, 0.0)
                    out[(r, "disturbance", i, rnd)] = {"m": m, "t": 9.0 + rnd}
        return out

    rows = {r.claim.id: r for r in evaluate(entry, summaries({}), 2, rounding=True)}
    for claim in ("a_below_b", "c_below_b"):
        result = rows[claim].result
        assert result.rounding_tested is False and result.rounding_robust is None
        assert result.changed == (False,) and rows[claim].verdict == result.main.verdict
    text = claims_markdown(list(rows.values()), 2)
    line = next(x for x in text.splitlines() if x.startswith("| a_below_b"))
    assert line.rstrip(" |").endswith("untested")
    assert "Path 1 changed no value a claim reads in any member: it tested nothing." in text
    assert "(u): the rounding rerun" in compact_table(list(rows.values()))
    # one ulp in C's second member: c_below_b is tested, a_below_b (A and B) still not, and
    # path 1 changed a value somewhere
    rows = {r.claim.id: r for r in evaluate(entry, summaries({"C": 2.0**-53}), 2,
                                            rounding=True)}
    assert rows["c_below_b"].result.rounding_tested is True
    assert rows["c_below_b"].result.rounding_robust is True
    assert rows["a_below_b"].result.rounding_tested is False
    text = claims_markdown(list(rows.values()), 2)
    assert "changed no value a claim reads in any member" not in text
    assert rows["c_below_b"].csv()["rounding_tested"] is True


def test_a_member_on_one_path_only_is_a_change() -> None:
    from cosim.reproduce.verdicts import changed_values

    both = {("A", "d", 0, 0): {"m": 1.0}, ("A", "d", 0, 1): {"m": 1.0}}
    assert not changed_values(both, ["A"], "d", 1, 1, ["m"])
    assert changed_values({**both, ("A", "d", 0, 1): None}, ["A"], "d", 1, 1, ["m"])
    assert not changed_values({}, ["A"], "d", 1, 1, ["m"])  # on neither path: no evidence
    nan = {("A", "d", 0, 0): {"m": math.nan}, ("A", "d", 0, 1): {"m": math.nan}}
    assert not changed_values(nan, ["A"], "d", 1, 1, ["m"])
    assert changed_values({**nan, ("A", "d", 0, 1): {}}, ["A"], "d", 1, 1, ["m"])


@pytest.mark.parametrize("value", [0, -3, 2.5, "10", True])
def test_bad_repeats_value_names_file_and_key(value: object) -> None:
    with pytest.raises(ClaimsError, match=f"e.toml: \\[ensemble\\] repeats = {value!r}"):
        check_ensemble("e.toml", {"repeats": value})


def test_repeat_claim_needs_repeats() -> None:
    with pytest.raises(ClaimsError, match="e.toml: \\[\\[claims\\]\\] 'a_below_b': ensemble "
                                          "= 'repeat' needs \\[ensemble\\] repeats"):
        check_claims("e.toml", [{**LESS, "ensemble": "repeat"}], ["A", "B"],
                     check_ensemble("e.toml", {}))


def test_repeat_claim_end_to_end_on_a_fast_entry(tmp_path: Path) -> None:
    import pandas as pd

    from cosim.reproduce.verdicts import run_claims

    path = tmp_path / "tiny.toml"
    path.write_text(
        'title = "t"\nbuild = "python"\n'
        '[[runs]]\nname = "A"\nscenario = "seed000_stop_pid"\n'
        '[[runs]]\nname = "B"\nscenario = "seed000_stop_pid_plain"\n'
        '[ensemble]\nreport_seeds = "1..3"\nrepeats = 3\n'
        '[[claims]]\nid = "a_faster"\ntext = "t"\nmetric = "wall_time_s"\nkind = "less"\n'
        'runs = ["A", "B"]\nensemble = "repeat"\n'
        '[[claims]]\nid = "a_within_bound"\ntext = "t"\nmetric = "wall_time_s"\n'
        'kind = "below"\nthreshold = 1e9\nruns = ["A"]\n')
    entry = load_entry(path)
    rows = {r.claim.id: r for r in run_claims(entry, tmp_path / "out", 2, workers=1)}
    assert rows["a_faster"].main.K == 3 and rows["a_faster"].result.rounding_robust is None
    assert rows["a_faster"].verdict == "insufficient"  # 3 repeats cannot decide a median
    # no seed key: the disturbance claim is one run, with its rounding rerun
    assert rows["a_within_bound"].main.K == 1 and rows["a_within_bound"].result.rounding_robust
    csv = pd.read_csv(tmp_path / "out" / "claims.csv")
    assert list(csv["K"]) == [3, 1]
    assert "n/a" in (tmp_path / "out" / "claims.md").read_text()


def test_a_second_rounding_path_perturbs_other_parameters_without_the_reference_path() -> None:
    """``rounding_perturb_second``: every perturbed member runs on a second path (2) with
    only its own parameters scaled by 1 + 1e-12 and no numpy reference path; it may not
    share a parameter with the first path."""
    from cosim.reproduce.ensemble import ROUNDING_RELATIVE
    from cosim.reproduce.members import ROUNDING_ENV, claim_jobs, member_jobs

    entry = _variant_entry()
    entry.ensemble = check_ensemble("e.toml", {
        "seed_key": "plant.seed", "report_seeds": "1..6", "rounding_perturb": ["plant.m"],
        "rounding_perturb_second": ["controller.k"]})
    entry.variants = []
    # a shipped scenario on its Python builds: path 1's environment is read from its FMUs
    entry.runs = [dataclasses.replace(r, scenario="seed000_stop_pid",
                                      overrides={"plant.m": 2.0, "controller.k": 3.0})
                  for r in entry.runs]
    jobs = {key: ov for key, _sc, ov in claim_jobs(entry, 2, rounding=True)}
    assert {key[3] for key in jobs} == {0, 1, 2}
    first, second = jobs["A", "disturbance", 1, 1], jobs["A", "disturbance", 1, 2]
    assert first["plant.m"] == 2.0 * (1 + ROUNDING_RELATIVE) and first["controller.k"] == 3.0
    assert second["controller.k"] == 3.0 * (1 + ROUNDING_RELATIVE) and second["plant.m"] == 2.0
    env = {job.key: job.env for job in member_jobs(entry, 2)}
    assert env["A", "disturbance", 1, 1] == ROUNDING_ENV
    assert env["A", "disturbance", 1, 2] == {} == env["A", "disturbance", 1, 0]
    with pytest.raises(ClaimsError, match="rounding_perturb_second shares"):
        check_ensemble("e.toml", {"rounding_perturb": ["plant.m"],
                                  "rounding_perturb_second": ["plant.m"]})


def test_path_1_takes_the_reference_environment_only_where_a_python_build_runs() -> None:
    """A member of native C builds alone has no numpy reference path: its path 1 runs (and
    is recorded) without ``ATO_COSIM_NO_KERNELS``, in the main path's workers; the same
    member on the Python builds, or with one FMU kept on its Python build by the run's own
    ``set``, takes it."""
    from cosim.reproduce.entry import load_entry
    from cosim.reproduce.members import ROUNDING_ENV, claim_jobs, member_env, member_jobs

    entry = load_entry("seed000")
    for build, expected in (("native", {}), ("python", ROUNDING_ENV)):
        envs = {job.key[3]: job.env for job in member_jobs(entry, 1, build=build)}
        assert envs[1] == expected and envs[0] == {}, build
    key, scenario, overrides = next(job for job in claim_jobs(entry, 1, build="native")
                                    if job[0][3] == 1)
    kept = {**overrides, "controller.build": "python"}
    assert member_env((key, scenario, kept), True) == ROUNDING_ENV
    assert member_env((key, scenario, overrides), False) == {}


def test_a_timing_run_records_its_machine_and_load_and_the_page_states_them() -> None:
    """Each run's summary carries ``host`` (CPU, cores, the 1-minute load average before
    and after); the repeat claims' note gives the machine and the load's range."""
    from cosim.reproduce.members import host_text, with_host
    from cosim.reproduce.verdicts import claims_markdown

    summary = with_host({"qp_cpu_time_total_s": 1.0}, 0.5)
    host = summary["host"]
    assert summary["qp_cpu_time_total_s"] == 1.0 and host["load_before"] == 0.5
    assert host["cores"] >= 1 and host["cpu"] and host["load_after"] >= 0.0
    runs = [{"host": {"cpu": "X", "cores": 2, "load_before": 0.5, "load_after": 3.25}},
            {"host": {"cpu": "X", "cores": 2, "load_before": 1.0, "load_after": 2.0}}, None]
    text = host_text(runs)
    assert text == "measured on X, 2 cores, 1-minute load average 0.5-3.2 over the repeats"
    assert host_text([{"qp": 1.0}, None]) == ""
    row = claim_row(id="t", text="t", metric="m", ensemble="repeat", origin="ours", k=10,
                    K=10, rounding_robust=None, median=-1.0, ci_low=-2.0, ci_high=-0.5)
    assert text in claims_markdown([row], 20, host=text)
