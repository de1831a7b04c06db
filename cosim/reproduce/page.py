"""What a reproduction makes of its record, and the command.

:func:`evaluate` makes everything after the simulations from the record and the entry alone:
the page ``table.md`` (the citation and what the paper claims; the verdicts: the headline, the
paper's statements, the claims grouped by origin; the paper's figures and sweeps redrawn; the
single runs, ours beside the paper's, derived figures and rankings; the notes) with
``table.csv``, and
``claims.*`` (:mod:`cosim.reproduce.verdicts`). :func:`redraw_entry` (``--redraw``) is that half
alone, :func:`reproduce` one entry end to end (:func:`cosim.reproduce.run.simulate`, the
record, :func:`evaluate`) and :func:`reproduce_all` every entry with one ``REPRODUCTION.md``."""

from __future__ import annotations

import re
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from cosim.reproduce.entry import (
    FIGURE_KINDS,
    Entry,
    ReproduceError,
    Statement,
    entry_names,
    load_entry,
    shipped,
)
from cosim.reproduce.figures import ensemble_lines, figure_section, sweep_section
from cosim.reproduce.members import host_text
from cosim.reproduce.record import (
    Record,
    RecordError,
    Summary,
    check_jobs,
    load,
    save,
    series_name,
)
from cosim.reproduce.run import (
    figure_runs,
    merged_summaries,
    simulate,
    table_seed,
    wanted_jobs,
)
from cosim.reproduce.series import run_scenarios
from cosim.reproduce.tables import (
    Cell,
    derived_markdown,
    derived_rows,
    md_row,
    ranking_markdown,
    ranking_rows,
    table_markdown,
    table_rows,
)
from cosim.reproduce.verdicts import (
    VERDICTS,
    ClaimRow,
    compact_table,
    failed_claims_markdown,
    final_verdict,
    verdict_summary,
    write_claims,
)
from cosim.run.console import fit_table
from cosim.run.provenance import INPUTS_FILE, entry_digest, simulation_digest
from cosim.run.results import locked_destination
from cosim.run.scenario import ROOT


@dataclass(frozen=True)
class Page:
    """What :func:`evaluate` made of a record."""

    table: Path  # the page's file (``table.md`` or the entry's ``table`` name)
    markdown: str  # its content
    rows: list[Cell]  # the table's cells (:func:`cosim.reproduce.tables.table_rows`)
    claim_rows: list[ClaimRow]  # one per claim (:func:`cosim.reproduce.verdicts.evaluate`)


def single_run_reruns(entry: Entry, record: Record) -> dict[str, list[Summary]]:
    """Run name -> the summaries of the table's single run on the perturbed floating-point
    paths: the reruns of member 1 of the disturbance ensemble, which is the single run
    (:func:`cosim.reproduce.run.table_seed`), where the record has them."""
    if not table_seed(entry):
        return {}
    out = {}
    for run in entry.runs:
        results = [record.results.get(("member", run.name, "disturbance", 0, path))
                   for path in entry.ensemble.rounding_paths()]
        if run.repeat == 1 and all(r is not None for r in results):
            out[run.name] = results
    return out


def entry_run(entry: Entry, name: str) -> Any:
    """The ``[[runs]]`` entry named ``name``."""
    return next(r for r in entry.runs if r.name == name)


def builds_sentence(entry: Entry, record: Record) -> str:
    """Which builds of the FMUs the record's table runs ran (``NAME.build`` of their jobs):
    "FMUs: native C builds of ...; Python builds of ..."."""
    scenarios = run_scenarios(entry)
    native: set[str] = set()
    python: set[str] = set()
    for job in record.jobs.values():
        if job.kind != "run":
            continue
        for comp in scenarios[job.key[0]].components.values():
            built = job.overrides.get(f"{comp.name}.build", comp.build)
            (native if built == "native" else python).add(Path(comp.fmu).stem)
    parts = [f"{what} builds of {', '.join(sorted(names))}"
             for what, names in (("native C", native), ("Python", python)) if names]
    return f"FMUs: {'; '.join(parts)} (`--build {record.build}`)." if parts else ""


def evaluate(entry: Entry, record: Record, out: Path, plot_format: str = "png") -> Page:
    """Tables, sweeps' tables and figures, figures, claims and the page of ``entry`` from
    ``record`` alone (no simulation; :class:`cosim.reproduce.record.RecordError` if the record
    lacks a job the entry reads): writes ``table.md`` / ``table.csv`` (``entry.table``),
    ``claims.*`` and the figures in ``plot_format`` to ``out``."""
    import pandas as pd

    check_jobs(record, wanted_jobs(entry, record.seeds, record.rounding, record.build))
    out.mkdir(parents=True, exist_ok=True)
    summaries = merged_summaries(entry, {job.key: record.results[ident]
                                         for ident, job in record.jobs.items()
                                         if job.kind == "run"})
    rows = table_rows(entry, summaries, single_run_reruns(entry, record))
    derived = derived_rows(entry, summaries)
    ranked = ranking_rows(entry, summaries)
    pd.DataFrame([r.csv() for r in [*rows, *derived, *ranked]]).to_csv(
        out / f"{entry.table}.csv", index=False)
    repeated = host_text([record.results[ident] for ident, job in record.jobs.items()
                          if job.kind == "run" and entry_run(entry, job.key[0]).repeat > 1])
    singles = [table_markdown(entry, rows) + (f"\n\nRepeated runs {repeated}." if repeated
                                              else "")]
    if derived:
        singles += ["", derived_markdown(derived)]
    if ranked:
        singles += ["", ranking_markdown(ranked)]
    claim_rows: list[ClaimRow] = []
    spread: dict[str, list[Path]] = {}  # a figure's file -> its ensemble figure's paths
    alias = f" (or `cosim reproduce {entry.alias}`)" if entry.alias else ""
    where = (entry.path.relative_to(ROOT).as_posix() if shipped(entry)
             else entry.path.name)
    source = (f"Reproduced by `cosim reproduce {entry.name}`{alias} from the entry `{where}`. "
              f"{builds_sentence(entry, record)}")
    verdicts: list[str] = []
    if entry.claims:  # the verdicts lead the page; the figures and single runs follow
        claim_rows, claims_text, spread = write_claims(entry, record, out, plot_format)
        lead = headline_markdown(entry.statements, claim_rows)
        stated = (["#### The paper's statements", "",
                   statements_markdown(entry.statements, claim_rows), ""]
                  if entry.statements else [])
        failed = failed_claims_markdown(claim_rows)
        verdicts = ["### Verdicts", "", verdict_summary(claim_rows, record.seeds), "",
                    *([lead, ""] if lead else []), *([failed, ""] if failed else []),
                    source.rstrip(), "", *stated,
                    "#### Claims: the paper's, then ours, then the sanity checks", "",
                    claims_text.rstrip("\n"), ""]
        singles[:0] = ["Each run once, as its scenario is shipped" + "".join(
            f", at report seed {v} (`{k}`: member 1 of the claims' disturbance ensemble)"
            for k, v in table_seed(entry).items())
            + " (the claims above are over the seed ensemble).", ""]
    drawn: list[str] = []
    scenarios = run_scenarios(entry)
    frames = {name: record.frame(series_name("run", name))
              for name in figure_runs(entry, FIGURE_KINDS)}
    for figure in entry.figures:
        drawn += figure_section(figure, frames, out, plot_format, scenarios)
        if figure.file in spread:
            drawn += ensemble_lines(figure, spread[figure.file], out, record.seeds)
    for sweep in entry.sweeps:
        drawn += sweep_section(sweep, record.result("sweep", sweep.name), out, plot_format)
    parts = [f"## {entry.title}", "", *citation_lines(entry),
             *(verdicts or [source.rstrip(), ""]),
             *(["### The paper's figures, redrawn", *drawn, ""] if drawn else []),
             "### Single runs", "", *singles]
    if entry.notes:
        parts += ["", "### Where we differ from the paper, and why", "", entry.notes.strip()]
    table = out / f"{entry.table}.md"
    markdown = "\n".join(parts) + "\n"
    table.write_text(markdown)
    return Page(table, markdown, rows, claim_rows)


def citation_lines(entry: Entry) -> list[str]:
    """The page's opening paragraphs: the citation with its DOI (or that the paper gives
    none), then what the paper claims (``summary``, as one paragraph)."""
    doi = (f"DOI [{entry.doi}](https://doi.org/{entry.doi})." if entry.doi
           else "DOI not given in the paper.")
    lines = [f"{entry.citation} {doi}" if entry.citation else doi, ""]
    if entry.summary:
        lines += [" ".join(entry.summary.split()), ""]
    return lines


def statement_reading(st: Statement, by_id: dict[str, ClaimRow]) -> str:
    """Whether a statement is reproduced, from the adjusted verdicts of its claims:
    "reproduced" when every claim holds, "not reproduced" when one fails, "undecided"
    otherwise (inconclusive, insufficient, rounding-sensitive or no effect)."""
    verdicts = [final_verdict(by_id[c]) for c in st.claims or []]
    if verdicts and all(v == "holds" for v in verdicts):
        return "reproduced"
    return "not reproduced" if "fails" in verdicts else "undecided"


def headline_markdown(statements: list[Statement], rows: list[ClaimRow]) -> str:
    """One line for the top of the page: each headline statement (``headline = true``) and
    whether it is reproduced, with the claims that decide it (those that do not hold, or all
    of them when every one holds)."""
    by_id = {r.claim.id: r for r in rows}
    items = []
    for st in statements:
        if not st.headline:
            continue
        reading = statement_reading(st, by_id)
        shown = [c for c in st.claims or []
                 if final_verdict(by_id[c]) != "holds"] or st.claims or []
        why = "; ".join(f"`{c}` {final_verdict(by_id[c])} "
                        f"{by_id[c].main.k}/{by_id[c].main.K}" for c in shown)
        items.append(f"{st.text}: **{reading}** ({why})")
    return ("**Headline** (the results the paper is about): " + ". ".join(items) + "."
            if items else "")


def statements_markdown(statements: list[Statement], rows: list[ClaimRow]) -> str:
    """Each of the paper's statements with the verdicts (adjusted) of the claims that test it,
    or why it is not tested."""
    by_id = {r.claim.id: r for r in rows}

    def where(st: Statement) -> str:  # its place in the paper: given, or its claims'
        return st.where or "; ".join(dict.fromkeys(
            by_id[c].claim.source for c in st.claims or [] if by_id[c].claim.source))

    lines = [md_row(["the paper says", "where", "tested by (verdict, k of K)"]),
             "| --- | --- | --- |"]
    for st in statements:
        if st.claims is not None:
            cell = "; ".join(f"`{c}`: {final_verdict(by_id[c])} "
                             f"({by_id[c].main.k}/{by_id[c].main.K})" for c in st.claims)
        else:
            cell = f"not tested: {st.untestable}"
        lines.append(md_row([st.text, where(st), cell]))
    n = sum(st.claims is not None for st in statements)
    lines += ["", f"{n} of {len(statements)} statements tested by a claim."]
    return "\n".join(lines)


def reproduce(name: str, out_dir: str | Path | None = None, workers: int | None = None,
              seeds: int | None = None, rounding: bool = True, scheduler: str | None = None,
              plot_format: str = "png", echo: bool = True, resume: bool = False,
              build: str | None = None, run_files: str = "figures") -> Path:
    """:func:`reproduce_page`'s file."""
    return reproduce_page(name, out_dir, workers, seeds, rounding, scheduler, plot_format,
                          echo, resume, build, run_files).table


def reproduce_page(name: str, out_dir: str | Path | None = None, workers: int | None = None,
                   seeds: int | None = None, rounding: bool = True,
                   scheduler: str | None = None, plot_format: str = "png", echo: bool = True,
                   resume: bool = False, build: str | None = None,
                   run_files: str = "figures") -> Page:
    """Run one entry (:func:`simulate`), keep its record (``record/``,
    :mod:`cosim.reproduce.record`) and write everything made of it (:func:`evaluate`): the tables,
    sweeps, figures (in ``plot_format``: png at 200 dpi with its svg beside it, svg or pdf;
    each line figure also over the claims' disturbance ensemble) and, with claims,
    claims.csv/claims.md over ``seeds`` members (default 20; :mod:`cosim.reproduce.members`,
    ``rounding``: also the perturbed floating-point rerun); every batch of runs goes through
    :mod:`cosim.run.runner` (``workers``, ``scheduler``). With ``echo`` the tables are printed
    in 80 columns (:func:`console_text`). With ``resume`` the jobs the folder's record already
    holds (same specification, simulation inputs, K, path and build) are not run again.
    ``build``: "native" runs the catalog FMUs' native C builds where they exist
    (:func:`cosim.reproduce.builds.build_overrides`), "python" every FMU's Python build, None the
    entry's ``build``. ``run_files``: what each table run writes under ``runs/``
    (:func:`cosim.reproduce.run.run_entry`)."""
    entry = load_entry(name)
    out = Path(out_dir) if out_dir is not None else Path("runs") / "reproduce" / entry.name
    with locked_destination(out):
        return _reproduce_into(entry, name, out, workers, seeds, rounding, scheduler,
                               plot_format, echo, resume, build, run_files)


def _reproduce_into(entry: Entry, name: str, out: Path, workers: int | None,
                    seeds: int | None, rounding: bool, scheduler: str | None,
                    plot_format: str, echo: bool, resume: bool, build: str | None,
                    run_files: str = "figures") -> Page:
    """:func:`reproduce_page` into the folder ``out``, which this process holds locked."""
    inputs = out / INPUTS_FILE
    inputs.unlink(missing_ok=True)  # a folder being rewritten vouches for no inputs
    need = entry.ensemble.declared_k()
    if entry.claims and seeds is not None and seeds < need:
        print(f"warning: --seeds {seeds} is below the {need} members {entry.name} declares "
              f"for a page: claims a small K cannot decide read 'insufficient', and `cosim "
              f"docs` does not publish this run", file=sys.stderr, flush=True)
    previous = None
    if resume:
        try:
            previous = load(out)
        except RecordError as err:
            print(f"{name}: nothing to resume ({err}): everything runs", file=sys.stderr,
                  flush=True)
    record = simulate(entry, out, workers, seeds, rounding, scheduler, plot_format, previous,
                      build, run_files)
    save(record, out)
    # the page is made from the record as stored (its series at SERIES_DIGITS digits), so
    # --redraw makes it again byte for byte
    return redraw_page(name, out, plot_format, echo)


def redraw_entry(name: str, out_dir: str | Path | None = None, plot_format: str = "png",
                 echo: bool = True) -> Path:
    """:func:`redraw_page`'s file, the folder locked meanwhile (a missing folder is not
    made: :func:`redraw_page` says it holds no record)."""
    out = (Path(out_dir) if out_dir is not None
           else Path("runs") / "reproduce" / load_entry(name).name)
    if not out.is_dir():
        return redraw_page(name, out, plot_format, echo).table
    with locked_destination(out):
        return redraw_page(name, out, plot_format, echo).table


def redraw_page(name: str, out_dir: str | Path | None = None, plot_format: str = "png",
                echo: bool = True) -> Page:
    """Tables, figures, claims and page of entry ``name`` from the record in ``out_dir``
    (default ``runs/reproduce/NAME``) without simulating (:func:`evaluate`); the folder's
    ``inputs.sha256`` then names the inputs of both (:func:`cosim.run.provenance.
    entry_digest`) when the record's simulation inputs are the tree's. With ``echo`` the
    tables are printed in 80 columns (:func:`console_text`)."""
    entry = load_entry(name)
    out = Path(out_dir) if out_dir is not None else Path("runs") / "reproduce" / entry.name
    record = load(out)
    if record.entry != entry.name:
        raise ReproduceError(f"{out}: the record is of {record.entry!r}, not {entry.name!r}")
    inputs = out / INPUTS_FILE
    inputs.unlink(missing_ok=True)
    try:
        page = evaluate(entry, record, out, plot_format)
    except RecordError as err:
        raise ReproduceError(str(err)) from err
    if (shipped(entry)
            and record.simulation == simulation_digest(entry.name, record.build)):
        inputs.write_text(entry_digest(entry.name, record.build) + "\n")
    if echo:
        print(console_text(entry, page.rows, page.claim_rows, out), flush=True)
    return page


def console_text(entry: Entry, rows: list[Cell], claim_rows: list[ClaimRow],
                 out: Path) -> str:
    """The entry's results for an 80-column terminal: ours per run and metric (columns
    numbered, their names below), the claims (id, k of K, verdict) and where the full tables
    are."""
    import textwrap

    names = {m.key: f"m{i + 1}" for i, m in enumerate(entry.metrics)}
    by_run: dict[str, dict[str, Any]] = {}
    for r in rows:
        by_run.setdefault(r.run, {"run": r.run})[names[r.metric]] = r.ours
    lines = textwrap.wrap(entry.title, 80)
    if by_run:
        lines += ["", fit_table(list(by_run.values()), ["run", *names.values()],
                                title="ours (beside the paper's, with verdicts, in "
                                      f"{entry.table}.md)")]
        lines += textwrap.wrap("; ".join(f"{names[m.key]} {m.heading}"
                                         for m in entry.metrics), 80)
    if claim_rows:
        lines += ["", compact_table(claim_rows)]
    full = [f"{entry.table}.md", f"{entry.table}.csv"]
    if claim_rows:
        full += ["claims.md", "claims.csv"]
    lines += ["", f"full tables in {out}/:", "  " + ", ".join(full)]  # a path is never cut
    return "\n".join(lines)


def claims_summary(claims: dict[str, list[ClaimRow]]) -> str:
    """Claims per verdict (after the multiplicity adjustment) per entry, from each entry's
    claims' rows (an entry without claims: dashes)."""
    lines = [md_row(["entry", "claims", *VERDICTS]), "|" + " --- |" * (2 + len(VERDICTS))]
    for name, rows in claims.items():
        if not rows:
            lines.append(md_row([name, "0", *("-" for _ in VERDICTS)]))
            continue
        got = [final_verdict(r) for r in rows]
        lines.append(md_row([name, str(len(got)), *(str(got.count(v)) for v in VERDICTS)]))
    return "\n".join(lines)


def reproduce_all(out_dir: str | Path | None = None, workers: int | None = None,
                  seeds: int | None = None, rounding: bool = True,
                  scheduler: str | None = None, plot_format: str = "png",
                  build: str | None = None, resume: bool = False,
                  run_files: str = "figures") -> Path:
    """Every entry; one ``REPRODUCTION.md`` with the claims held / failed / inconclusive per
    paper and each entry's tables and figures."""
    out = Path(out_dir) if out_dir is not None else Path("runs") / "reproduce"
    with locked_destination(out):
        pages = {name: reproduce_page(name, out / name, workers, seeds, rounding, scheduler,
                                      plot_format, resume=resume, build=build,
                                      run_files=run_files)
                 for name in entry_names()}
        parts = ["# Reproduced results", "", "Made by `cosim reproduce all`; each section by "
                 "`cosim reproduce NAME` from the entry `papers/NAME/entry.toml`.", "",
                 claims_summary({name: page.claim_rows for name, page in pages.items()})]
        for name, page in pages.items():
            # relative links from out/: prefix the entry folder
            text = re.sub(r"\]\((?!http)([^)]+)\)", rf"]({name}/\1)", page.markdown)
            parts += ["", text]
        path = out / "REPRODUCTION.md"
        path.write_text("\n".join(parts) + "\n")
        return path
