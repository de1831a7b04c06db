"""The tables of a reproduction entry made from its runs' summaries, in the long format of
``table.csv`` (one row per figure): ours beside the paper's per (run, metric) with the verdict
where the entry gives a band or a tolerance (:func:`table_rows`), the derived figures
(``metric = "<kind>:<metric>"``, :func:`derived_rows`) and the rankings
(``metric = "rank:<metric>"``, :func:`ranking_rows`); and their markdown on the page."""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from cosim.reproduce.entry import Entry
from cosim.reproduce.numbers import decimals_for, fixed
from cosim.reproduce.record import Summary
from cosim.reproduce.stats import ratio_ci


def summary_value(summary: Summary, key: str) -> Any:
    """``summary["a"]["b"]`` for ``key = "a.b"``; None where absent."""
    value: Any = summary
    for part in key.split("."):
        if not isinstance(value, dict) or part not in value:
            return None
        value = value[part]
    return value


def repeat_values(summary: Summary, key: str) -> list[float] | None:
    """A metric's value in every repetition of a repeated run (None if not repeated or not
    numeric)."""
    reps = summary.get("repeats")
    if not reps:
        return None
    vals = [summary_value(r, key) for r in reps]
    if not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in vals):
        return None
    return [float(v) for v in vals]


def repeat_spread(summary: Summary, key: str) -> tuple[float, float, int] | None:
    """``(min, max, n)`` of a metric over a repeated run's repetitions (None if not repeated
    or not numeric)."""
    vals = repeat_values(summary, key)
    return None if vals is None else (min(vals), max(vals), len(vals))


def md_row(cells: list[str]) -> str:
    """A markdown table row of one line: a ``|`` inside a cell (``max |e|``) is escaped and a
    line break (a multi-line TOML string) becomes a space, so the row keeps its cells."""
    return "| " + " | ".join(" ".join(str(c).replace("|", "\\|").splitlines())
                             for c in cells) + " |"


def fmt(value: Any, decimals: int | None = None) -> str:
    """A value in a markdown cell: "-" for none, yes / no, a number in fixed notation with
    ``decimals`` decimals (its column's, :func:`cosim.reproduce.numbers.decimals_for`; None: its
    own), a text as it is."""
    if value is None:
        return "-"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, numbers.Real):
        return fixed(float(value), decimals_for([value]) if decimals is None else decimals)
    return str(value)


def given(value: float | None) -> str:
    """A figure of the paper as the entry gives it: positional, its digits (0.9249, 324)."""
    return "-" if value is None else np.format_float_positional(value, trim="-")


@dataclass(frozen=True)
class Ratio:
    """A cell's ratio to the ``ratio_to`` run (of the medians where the runs are repeated)."""

    value: float | None  # ours / the ratio_to run's
    ci_low: float | None  # its 95 % bootstrap CI where both runs are repeated
    ci_high: float | None
    paper: float | None  # the paper's ratio where the paper gives both figures


@dataclass(frozen=True)
class Cell:
    """One (run, metric) of the table: ours beside the paper's, and the verdict."""

    run: str
    metric: str  # the [[metrics]] key
    ours: Any  # the summary's value (a number, a bool or a text; None where absent)
    ours_min: float | None  # the spread over a repeated run's repetitions
    ours_max: float | None
    repeats: int  # the run's repetitions
    paper: float | None  # the paper's value, in the metric's unit
    paper_range: list[float] | None  # the paper's band [low, high]
    tolerance: float | None
    source: str  # where the paper gives it
    ratio: Ratio | None  # with the metric's ratio_to
    within: bool | None  # inside the band and the tolerance (None: nothing to judge)
    # the printed figure differs on the same run's perturbed floating-point rerun (None: the
    # record has no such rerun of this run)
    rounding_moves: bool | None = None
    # the decimals of the metric's column (:func:`column_decimals`; None: the value's own)
    decimals: int | None = None

    def csv(self) -> dict[str, Any]:
        """The row of ``table.csv``."""
        row = {"run": self.run, "metric": self.metric, "ours": self.ours,
               "ours_min": self.ours_min, "ours_max": self.ours_max, "repeats": self.repeats,
               "paper": self.paper, "paper_range": self.paper_range,
               "tolerance": self.tolerance, "source": self.source}
        if self.ratio is not None:
            row |= {"ratio": self.ratio.value, "ratio_ci_low": self.ratio.ci_low,
                    "ratio_ci_high": self.ratio.ci_high, "paper_ratio": self.ratio.paper}
        return row | {"within": self.within, "rounding_moves": self.rounding_moves}


@dataclass(frozen=True)
class DerivedRow:
    """One ``[[derived]]`` figure (its ``table.csv`` row: these fields, in this order)."""

    run: str  # the derived figure's name
    metric: str  # "<kind>:<metric>"
    ours: float | None  # in % for saving_percent
    paper: float | None
    paper_range: list[float] | None
    tolerance: float | None
    source: str
    within: bool | None
    of: str  # "<run> against <baseline>"

    def csv(self) -> dict[str, Any]:
        """The row of ``table.csv``."""
        return {f.name: getattr(self, f.name) for f in fields(self)}


@dataclass(frozen=True)
class RankingRow:
    """One ``[[rankings]]`` (its ``table.csv`` row: these fields, in this order)."""

    run: str  # the ranking's name
    metric: str  # "rank:<metric>"
    label: str  # the metric's heading
    ours: str  # the runs in our order, lowest first ("A < B")
    paper: str | None  # the paper's order
    within: bool | None  # no pair the other way round (None: no paper order)
    source: str  # the pairs ours orders the other way round ("B < A; ...")

    def csv(self) -> dict[str, Any]:
        """The row of ``table.csv``."""
        return {f.name: getattr(self, f.name) for f in fields(self)}


def _within(ours: Any, band: list[float] | None, value: float | None,
            tolerance: float | None) -> bool | None:
    """Ours inside the paper's band and within the tolerance of its value (None: neither is
    given, or there is no figure of ours)."""
    within = None
    if ours is not None and band is not None:
        within = band[0] <= float(ours) <= band[1]
    if ours is not None and tolerance is not None and value is not None:
        close = abs(float(ours) - float(value)) <= tolerance
        within = close if within is None else within and close
    return within


def table_rows(entry: Entry, summaries: dict[str, Summary],
               perturbed: dict[str, list[Summary]] | None = None) -> list[Cell]:
    """Long format: one cell per (run, metric) with ours, the paper's and the verdict;
    ``perturbed`` (run name -> the summaries of the same run on the perturbed floating-point
    paths, where it has them) marks the cells whose printed figure one of them moves."""
    perturbed = perturbed or {}
    refs = {(r.run, r.metric): r for r in entry.paper}
    rows = []
    decimals = {m.key: column_decimals(entry, summaries, m.key) for m in entry.metrics}
    for run in entry.runs:
        for metric in entry.metrics:
            ours = summary_value(summaries[run.name], metric.key)
            places = decimals[metric.key]
            ref = refs.get((run.name, metric.key))
            value = ref.value if ref is not None else None
            band = ref.band if ref is not None else None
            tolerance = ref.tolerance if ref is not None else None
            spread = repeat_spread(summaries[run.name], metric.key)
            ratio = None
            if metric.ratio_to is not None:
                ratio = _ratio(summaries, refs, run.name, metric.ratio_to, metric.key, ours,
                               value)
            rows.append(Cell(run=run.name, metric=metric.key, ours=ours,
                             ours_min=spread[0] if spread else None,
                             ours_max=spread[1] if spread else None,
                             repeats=spread[2] if spread else 1, paper=value,
                             paper_range=band, tolerance=tolerance,
                             source=ref.source if ref is not None else "", ratio=ratio,
                             within=_within(ours, band, value, tolerance), decimals=places,
                             rounding_moves=(
                                 None if run.name not in perturbed or spread else
                                 any(fmt(summary_value(s, metric.key), places)
                                     != fmt(ours, places) for s in perturbed[run.name]))))
    return rows


def column_decimals(entry: Entry, summaries: dict[str, Summary], key: str) -> int:
    """The fixed notation of metric ``key``'s column (:func:`cosim.reproduce.numbers.decimals_for`
    of every run's value and repetitions)."""
    values: list[Any] = []
    for run in entry.runs:
        values.append(summary_value(summaries[run.name], key))
        values += repeat_values(summaries[run.name], key) or []
    return decimals_for(values)


def _ratio(summaries: dict[str, Summary], refs: dict[tuple[str, str], Any], run: str,
           base_run: str, key: str, ours: Any, value: float | None) -> Ratio:
    """The ratio of ``run``'s ``key`` to ``base_run``'s, with its CI and the paper's."""
    base = summary_value(summaries[base_run], key)
    base_given = refs.get((base_run, key))
    base_ref = base_given.value if base_given is not None else None
    low = high = None
    # repeated runs: the ratio of medians with its bootstrap CI
    ours_reps = repeat_values(summaries[run], key)
    base_reps = repeat_values(summaries[base_run], key)
    if ours_reps is not None and base_reps is not None:
        _, lo, hi = ratio_ci(np.array(ours_reps), np.array(base_reps))
        if np.isfinite(lo) and np.isfinite(hi):
            low, high = lo, hi
    return Ratio(value=float(ours) / float(base) if ours is not None and base else None,
                 ci_low=low, ci_high=high,
                 paper=float(value) / float(base_ref) if value is not None and base_ref
                 else None)


def derived_rows(entry: Entry, summaries: dict[str, Summary]) -> list[DerivedRow]:
    """One row per ``[[derived]]`` figure, in the long format of :func:`table_rows`."""
    rows = []
    for der in entry.derived:
        ours = None
        run = summary_value(summaries[der.run], der.metric)
        base = summary_value(summaries[der.baseline], der.metric)
        if run is not None and base not in (None, 0):
            ours = 100.0 * (1.0 - float(run) / float(base))  # saving_percent
        rows.append(DerivedRow(run=der.name, metric=f"{der.kind}:{der.metric}", ours=ours,
                               paper=der.value, paper_range=der.band,
                               tolerance=der.tolerance, source=der.source,
                               within=_within(ours, der.band, der.value, der.tolerance),
                               of=f"{der.run} against {der.baseline}"))
    return rows


def ranking_rows(entry: Entry, summaries: dict[str, Summary]) -> list[RankingRow]:
    """One row per ``[[rankings]]``: the runs ordered by the metric (lowest first; equal values
    keep the entry's order), the paper's order and the pairs ordered the other way round
    (``within``: no such pair). A run without the metric ranks last."""
    def value(run: str, metric: str) -> float:
        v = summary_value(summaries[run], metric)
        return math.inf if v is None or (isinstance(v, float) and math.isnan(v)) else float(v)

    rows = []
    for rank in entry.rankings:
        ours = sorted(rank.runs, key=lambda run, m=rank.metric: value(run, m))
        paper = rank.paper
        swapped = []
        if paper is not None:
            place = {run: i for i, run in enumerate(ours)}
            swapped = [f"{b} < {a}" for i, a in enumerate(paper) for b in paper[i + 1:]
                       if place[b] < place[a]]
        label = next(m.heading for m in entry.metrics if m.key == rank.metric)
        rows.append(RankingRow(run=rank.name, metric=f"rank:{rank.metric}", label=label,
                               ours=" < ".join(ours),
                               paper=" < ".join(paper) if paper is not None else None,
                               within=None if paper is None else not swapped,
                               source="; ".join(swapped)))
    return rows


def _mark(within: bool | None) -> str:
    """The verdict mark after a figure: " ✓", " ✗" or nothing."""
    return "" if within is None else (" ✓" if within else " ✗")


def _given(paper: float | None, band: list[float] | None) -> str:
    """The paper's figure: its value, its band, or both."""
    shown = given(paper)
    if band is not None:
        text = f"in [{given(band[0])}, {given(band[1])}]"
        shown = text if paper is None else f"{shown} ({text})"
    return shown


def ranking_markdown(rows: list[RankingRow]) -> str:
    """The rankings below the table: ours against the paper's order."""
    lines = ["| ranking (lowest first) | runs | ours | paper | the other way round |",
             "| --- | --- | --- | --- | --- |"]
    for r in rows:
        lines.append(md_row([r.label, r.run, r.ours + _mark(r.within), fmt(r.paper),
                             r.source or "-"]))
    return "\n".join(lines)


def derived_markdown(rows: list[DerivedRow]) -> str:
    """The derived figures below the table: ours beside the paper's."""
    lines = ["| derived figure | of | ours | paper | source |", "| --- | --- | --- | --- | --- |"]
    places = decimals_for(r.ours for r in rows)
    for r in rows:
        lines.append(md_row([f"{r.run} ({r.metric})", r.of, fmt(r.ours, places) + _mark(r.within),
                             _given(r.paper, r.paper_range), r.source]))
    return "\n".join(lines)


TABLE_COLUMNS = 9  # at most this many columns in one markdown table of a paper page


def table_markdown(entry: Entry, rows: list[Cell]) -> str:
    """A row per run; per metric an "ours" column and a "paper" column (left out where the
    paper gives no value for any run), and with ``ratio_to`` the ratio and the paper's. When
    the columns exceed :data:`TABLE_COLUMNS` the metrics are split over several tables, each
    repeating the run column (a metric's columns stay together)."""
    by = {(r.run, r.metric): r for r in rows}
    runs = entry.run_names()
    groups: list[list[tuple[str, list[str]]]] = []  # per metric: (header, cells per run)
    for metric in entry.metrics:
        label = metric.heading
        ours, paper, ratio, paper_ratio = [], [], [], []
        cells = [by[name, metric.key] for name in runs]
        ratios = [r.ratio for r in cells if r.ratio is not None]
        places = decimals_for(v for q in ratios for v in (q.value, q.ci_low, q.ci_high))
        paper_places = decimals_for(q.paper for q in ratios)
        for r in cells:
            value = fmt(r.ours, r.decimals)
            if r.ours_min is not None:
                value = f"{value} [{fmt(r.ours_min, r.decimals)}, {fmt(r.ours_max, r.decimals)}]"
            ours.append(value + ("‡" if r.rounding_moves else "") + _mark(r.within))
            paper.append(_given(r.paper, r.paper_range))
            if r.ratio is not None:
                text = fmt(r.ratio.value, places)
                if r.ratio.ci_low is not None:
                    text = (f"{text} ({fmt(r.ratio.ci_low, places)}-"
                            f"{fmt(r.ratio.ci_high, places)})")
                ratio.append(text)
                paper_ratio.append(fmt(r.ratio.paper, paper_places))
        columns = [(label, ours)]
        if any(c != "-" for c in paper):
            columns.append(("paper", paper))
        if metric.ratio_to is not None:
            columns.append((f"ratio to {metric.ratio_to}", ratio))
            if any(c != "-" for c in paper_ratio):
                columns.append(("paper", paper_ratio))
        groups.append(columns)
    tables: list[list[tuple[str, list[str]]]] = [[]]
    for columns in groups:
        if tables[-1] and 1 + len(tables[-1]) + len(columns) > TABLE_COLUMNS:
            tables.append([])
        tables[-1] += columns
    lines: list[str] = []
    for n, table in enumerate(tables):
        if n:
            lines.append("")
        header = ["run", *(head for head, _ in table)]
        lines += [md_row(header), "|" + " --- |" * len(header)]
        lines += [md_row([name, *(cells[i] for _, cells in table)])
                  for i, name in enumerate(runs)]
    sources = sorted({f"{r.run} / {r.metric}: {r.source}" for r in rows if r.source})
    if sources:
        lines += ["", "Paper figures: " + "; ".join(sources) + "."]
    repeated = sorted({r.repeats for r in rows if r.repeats > 1})
    if repeated:
        lines += ["", "a [b, c]: median [min, max] over the repetitions of a repeated run ("
                  + ", ".join(f"{n}" for n in repeated) + " runs); a ratio r (l-h) of two "
                  "repeated runs: the ratio of their medians with its 95 % bootstrap CI."]
    if any(r.rounding_moves for r in rows):
        lines += ["", "‡: the printed figure moves on a perturbed floating-point rerun of the "
                  "same run (its reruns as member 1 of the claims' ensemble): the digits it "
                  "moves are not a result."]
    if any(r.within is not None for r in rows):
        lines += ["", "✓ / ✗: inside / outside the paper's band or the tolerance stated in the "
                  "entry."]
    return "\n".join(lines)


def frame_markdown(frame: Any) -> str:
    """A data frame as a markdown table."""
    cols = list(frame.columns)
    places = {c: decimals_for(frame[c]) for c in cols}
    lines = [md_row(cols), "|" + " --- |" * len(cols)]
    for _, row in frame.iterrows():
        lines.append(md_row([fmt(row[c], places[c]) for c in cols]))
    return "\n".join(lines)
