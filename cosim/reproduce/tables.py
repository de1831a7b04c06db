"""The tables of a reproduction entry made from its runs' summaries, in the long format of
``table.csv`` (one row per figure): ours beside the paper's per (run, metric) with the verdict
where the entry gives a band or a tolerance (:func:`table_rows`), the derived figures
(``metric = "<kind>:<metric>"``, :func:`derived_rows`) and the rankings
(``metric = "rank:<metric>"``, :func:`ranking_rows`); and their markdown on the page."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from cosim.reproduce.entry import Entry
from cosim.run.claims import number, ratio_ci


def summary_value(summary: dict[str, Any], key: str) -> Any:
    """``summary["a"]["b"]`` for ``key = "a.b"``; None where absent."""
    value: Any = summary
    for part in key.split("."):
        if not isinstance(value, dict) or part not in value:
            return None
        value = value[part]
    return value


def repeat_values(summary: dict[str, Any], key: str) -> list[float] | None:
    """A metric's value in every repetition of a repeated run (None if not repeated or not
    numeric)."""
    reps = summary.get("repeats")
    if not reps:
        return None
    vals = [summary_value(r, key) for r in reps]
    if not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in vals):
        return None
    return [float(v) for v in vals]


def repeat_spread(summary: dict[str, Any], key: str) -> tuple[float, float, int] | None:
    """``(min, max, n)`` of a metric over a repeated run's repetitions (None if not repeated
    or not numeric)."""
    reps = summary.get("repeats")
    if not reps:
        return None
    vals = [summary_value(r, key) for r in reps]
    if not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in vals):
        return None
    return float(min(vals)), float(max(vals)), len(vals)


def md_row(cells: list[str]) -> str:
    """A markdown table row; a ``|`` inside a cell (``max |e|``) is escaped."""
    return "| " + " | ".join(str(c).replace("|", "\\|") for c in cells) + " |"


def fmt(value: Any) -> str:
    if value is None:
        return "-"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float):
        return number(value)
    return str(value)


def table_rows(entry: Entry, summaries: dict[str, dict[str, Any]]) -> list[dict[str, Any]]:
    """Long format: one row per (run, metric) with ours, the paper's and the verdict."""
    refs = {(r.run, r.metric): r for r in entry.paper}
    rows = []
    for run in entry.runs:
        for metric in entry.metrics:
            ours = summary_value(summaries[run.name], metric.key)
            ref = refs.get((run.name, metric.key))
            value = ref.value if ref is not None else None
            band = ref.band if ref is not None else None
            spread = repeat_spread(summaries[run.name], metric.key)
            row = {"run": run.name, "metric": metric.key, "ours": ours,
                   "ours_min": spread[0] if spread else None,
                   "ours_max": spread[1] if spread else None,
                   "repeats": spread[2] if spread else 1,
                   "paper": value, "paper_range": band,
                   "tolerance": ref.tolerance if ref is not None else None,
                   "source": ref.source if ref is not None else ""}
            base_run = metric.ratio_to
            if base_run is not None:
                base = summary_value(summaries[base_run], metric.key)
                base_given = refs.get((base_run, metric.key))
                base_ref = base_given.value if base_given is not None else None
                row["ratio"] = (float(ours) / float(base) if ours is not None and base
                                else None)
                # repeated runs: the ratio of medians with its bootstrap CI
                ours_reps = repeat_values(summaries[run.name], metric.key)
                base_reps = repeat_values(summaries[base_run], metric.key)
                row["ratio_ci_low"] = row["ratio_ci_high"] = None
                if ours_reps is not None and base_reps is not None:
                    _, lo, hi = ratio_ci(np.array(ours_reps), np.array(base_reps))
                    if np.isfinite(lo) and np.isfinite(hi):
                        row["ratio_ci_low"], row["ratio_ci_high"] = lo, hi
                row["paper_ratio"] = (float(value) / float(base_ref)
                                      if value is not None and base_ref else None)
            within = None
            if ours is not None and band is not None:
                within = band[0] <= float(ours) <= band[1]
            if ours is not None and row["tolerance"] is not None:
                close = abs(float(ours) - float(value)) <= row["tolerance"]
                within = close if within is None else within and close
            row["within"] = within
            rows.append(row)
    return rows


def derived_rows(entry: Entry, summaries: dict[str, dict[str, Any]]) -> list[dict[str, Any]]:
    """One row per ``[[derived]]`` figure, in the long format of :func:`table_rows`."""
    rows = []
    for der in entry.derived:
        ours = None
        run = summary_value(summaries[der.run], der.metric)
        base = summary_value(summaries[der.baseline], der.metric)
        if run is not None and base not in (None, 0):
            ours = 100.0 * (1.0 - float(run) / float(base))  # saving_percent
        band = der.band
        within = None
        if ours is not None and band is not None:
            within = band[0] <= ours <= band[1]
        if ours is not None and der.tolerance is not None and der.value is not None:
            close = abs(ours - float(der.value)) <= der.tolerance
            within = close if within is None else within and close
        rows.append({"run": der.name, "metric": f"{der.kind}:{der.metric}",
                     "ours": ours, "paper": der.value, "paper_range": band,
                     "tolerance": der.tolerance, "source": der.source,
                     "within": within,
                     "of": f"{der.run} against {der.baseline}"})
    return rows


def ranking_rows(entry: Entry, summaries: dict[str, dict[str, Any]]) -> list[dict[str, Any]]:
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
        rows.append({"run": rank.name, "metric": f"rank:{rank.metric}",
                     "label": label, "ours": " < ".join(ours),
                     "paper": " < ".join(paper) if paper is not None else None,
                     "within": None if paper is None else not swapped,
                     "source": "; ".join(swapped)})
    return rows


def ranking_markdown(rows: list[dict[str, Any]]) -> str:
    lines = ["| ranking (lowest first) | runs | ours | paper | the other way round |",
             "| --- | --- | --- | --- | --- |"]
    for r in rows:
        mark = "" if r["within"] is None else (" ✓" if r["within"] else " ✗")
        lines.append(md_row([r["label"], r["run"], r["ours"] + mark, fmt(r["paper"]),
                           r["source"] or "-"]))
    return "\n".join(lines)


def derived_markdown(rows: list[dict[str, Any]]) -> str:
    lines = ["| derived figure | of | ours | paper | source |", "| --- | --- | --- | --- | --- |"]
    for r in rows:
        mark = "" if r["within"] is None else (" ✓" if r["within"] else " ✗")
        paper = fmt(r["paper"])
        if r["paper_range"] is not None:
            band = f"in [{fmt(r['paper_range'][0])}, {fmt(r['paper_range'][1])}]"
            paper = band if r["paper"] is None else f"{paper} ({band})"
        lines.append(md_row([f"{r['run']} ({r['metric']})", r["of"], fmt(r["ours"]) + mark,
                           paper, r["source"]]))
    return "\n".join(lines)


TABLE_COLUMNS = 9  # at most this many columns in one markdown table of a paper page


def table_markdown(entry: Entry, rows: list[dict[str, Any]]) -> str:
    """A row per run; per metric an "ours" column and a "paper" column (left out where the
    paper gives no value for any run), and with ``ratio_to`` the ratio and the paper's. When
    the columns exceed :data:`TABLE_COLUMNS` the metrics are split over several tables, each
    repeating the run column (a metric's columns stay together)."""
    by = {(r["run"], r["metric"]): r for r in rows}
    runs = entry.run_names()
    groups: list[list[tuple[str, list[str]]]] = []  # per metric: (header, cells per run)
    for metric in entry.metrics:
        label = metric.heading
        ours, paper, ratio, paper_ratio = [], [], [], []
        for name in runs:
            r = by[name, metric.key]
            mark = "" if r["within"] is None else (" ✓" if r["within"] else " ✗")
            given = fmt(r["paper"])
            if r["paper_range"] is not None:
                band = f"in [{fmt(r['paper_range'][0])}, {fmt(r['paper_range'][1])}]"
                given = band if r["paper"] is None else f"{given} ({band})"
            value = fmt(r["ours"])
            if r["ours_min"] is not None:
                value = f"{value} [{fmt(r['ours_min'])}, {fmt(r['ours_max'])}]"
            ours.append(value + mark)
            paper.append(given)
            if metric.ratio_to is not None:
                text = fmt(r["ratio"])
                if r.get("ratio_ci_low") is not None:
                    text = f"{text} ({fmt(r['ratio_ci_low'])}-{fmt(r['ratio_ci_high'])})"
                ratio.append(text)
                paper_ratio.append(fmt(r["paper_ratio"]))
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
    sources = sorted({f"{r['run']} / {r['metric']}: {r['source']}" for r in rows if r["source"]})
    if sources:
        lines += ["", "Paper figures: " + "; ".join(sources) + "."]
    repeated = sorted({r["repeats"] for r in rows if r["repeats"] > 1})
    if repeated:
        lines += ["", "a [b, c]: median [min, max] over the repetitions of a repeated run ("
                  + ", ".join(f"{n}" for n in repeated) + " runs); a ratio r (l-h) of two "
                  "repeated runs: the ratio of their medians with its 95 % bootstrap CI."]
    if any(r["within"] is not None for r in rows):
        lines += ["", "✓ / ✗: inside / outside the paper's band or the tolerance stated in the "
                  "entry."]
    return "\n".join(lines)


def frame_markdown(frame: Any) -> str:
    cols = list(frame.columns)
    lines = [md_row(cols), "|" + " --- |" * len(cols)]
    for _, row in frame.iterrows():
        lines.append(md_row([fmt(row[c]) for c in cols]))
    return "\n".join(lines)
