"""The simulations of a reproduction entry: its table runs (with repetitions), sweeps and the
claims' members (:mod:`cosim.reproduce.members`), run through :mod:`cosim.run.runner`, and the
:class:`cosim.reproduce.record.Record` of their results and of the series the figures draw."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

from cosim.reproduce.builds import build_overrides
from cosim.reproduce.entry import FIGURE_KINDS, Entry, Figure, ReproduceError, shipped, slug
from cosim.reproduce.members import (
    MEMBER_INSTANCES,
    host_load,
    member_jobs,
    member_scenario,
    simulate_claims,
    with_host,
)
from cosim.reproduce.record import Job, Overrides, Record, Summary, known, save, series_name
from cosim.reproduce.series import record_series, run_scenarios
from cosim.run import runner
from cosim.run.provenance import simulation_digest
from cosim.run.results import _json_safe as json_safe
from cosim.run.scenario import load_scenario
from cosim.run.simulate import ensure_built, run_scenario
from cosim.run.sweep import parse_grid, run_sweep, warm_up_for

RUN_FILES = ("figures", "all")  # --run-files: what each table run writes into runs/<run>/


def _run_one(scenario: str, overrides: Overrides, out_dir: str, write: str,
             plot_format: str = "png") -> Summary:
    """One table run of ``scenario`` with ``overrides`` (a task) on this worker's FMU
    instances (:data:`cosim.reproduce.members.MEMBER_INSTANCES`): its summary, with into
    ``out_dir`` per ``write``: "all" results.csv, results.units.json, summary.json and the
    run's plot (as ``cosim run`` writes them); "csv" the same without the plot; "summary"
    summary.json alone, the run recording only what its summary reads
    (:func:`cosim.reproduce.members.member_scenario`)."""
    before = host_load()
    sc = load_scenario(scenario, overrides)
    if write == "summary":
        summary = run_scenario(member_scenario(sc), build=False, plot=False,
                               pool=MEMBER_INSTANCES).summary
        folder = Path(out_dir)
        folder.mkdir(parents=True, exist_ok=True)
        (folder / "summary.json").write_text(json.dumps(json_safe(summary), indent=2) + "\n")
    else:
        summary = run_scenario(sc, out_dir=out_dir, build=False, plot=write == "all",
                               plot_format=plot_format, pool=MEMBER_INSTANCES).summary
    return with_host(summary, before)


def _merge_repeats(summaries: list[Summary]) -> Summary:
    """The first summary, each numeric value replaced by the median over the repetitions;
    ``repeats`` holds every repetition's summary."""
    import statistics

    def merge(values: list[Any]) -> Any:
        first = values[0]
        if isinstance(first, dict):
            return {k: merge([v.get(k) if isinstance(v, dict) else None for v in values])
                    for k in first}
        nums = [v for v in values if isinstance(v, (int, float)) and not isinstance(v, bool)]
        if len(nums) == len(values) and not isinstance(first, bool):
            return statistics.median(nums)
        return first

    merged = merge(summaries)
    merged["repeats"] = summaries
    return merged


def table_seed(entry: Entry) -> dict[str, int]:
    """The random input of the table's single runs: ``[ensemble] seed_key`` at the first
    report seed (so a single run is member 1 of the claims' ensemble), or nothing where the
    entry has no random input."""
    key = entry.ensemble.seed_key
    return {key: entry.ensemble.report_seeds[0]} if key and entry.ensemble.report_seeds else {}


def run_jobs(entry: Entry, build: str = "python") -> list[Job]:
    """The table runs' simulations: one job per run and repetition, at :func:`table_seed`
    unless the run sets its seed itself, on ``build`` (:func:`build_overrides`)."""
    seed = table_seed(entry)
    return [Job("run", (run.name, k), run.scenario,
                {**build_overrides(run.scenario, run.overrides, build), **seed,
                 **run.overrides})
            for run in entry.runs for k in range(run.repeat)]


def sweep_jobs(entry: Entry, build: str = "python") -> list[Job]:
    """One job per ``[[sweeps]]`` entry (its scenarios and grid; on ``build``, each
    :func:`build_overrides` key as a one-value axis after the sweep's own)."""
    jobs = []
    for sweep in entry.sweeps:
        grid = dict(sweep.grid)
        for scenario in sweep.scenarios:
            for key, value in build_overrides(scenario, grid, build).items():
                grid.setdefault(key, value)
        jobs.append(Job("sweep", (sweep.name,), list(sweep.scenarios), grid))
    return jobs


def run_entry(entry: Entry, out_dir: Path, workers: int | None = None,
              scheduler: str | None = None, plot_format: str = "png",
              record: Record | None = None, previous: Record | None = None,
              build: str = "python", run_files: str = "figures") -> dict[str, Summary]:
    """Run every run of ``entry`` on ``build`` with :func:`cosim.run.runner.run_tasks`
    (``workers`` processes or the Dask ``scheduler``; a run with ``repeat = k`` k times,
    repetitions 2.. under ``runs/<run>/repeat_NN``); returns run name -> summary (medians and
    ``repeats`` for a repeated run), each repetition's summary added to ``record``; a run
    ``previous`` holds with the same specification is taken from it, not run again. A failed
    run raises
    :class:`ReproduceError` naming it, after the others finished. ``run_files`` (one of
    :data:`RUN_FILES`): "figures" writes results.csv only for the first repetition of a run a
    figure draws (the record's series are read from it) and summary.json for every run;
    "all" every run's results.csv and plot in ``plot_format`` too."""
    jobs = run_jobs(entry, build)
    for job in jobs:  # bad overrides fail here, before anything runs; build once
        if job.key[1] == 0:
            ensure_built(load_scenario(job.scenario, job.overrides))
    if run_files not in RUN_FILES:
        raise ReproduceError(f"--run-files {run_files}: one of {', '.join(RUN_FILES)}")
    drawn = set(figure_runs(entry, FIGURE_KINDS))
    tasks = []
    done: dict[Any, Summary] = {}
    for job in jobs:
        if previous is not None and known(previous, job):
            done[job.key] = previous.result(job.kind, *job.key)
            continue
        name, k = job.key
        base = out_dir / "runs" / slug(name)
        out = base if k == 0 else base / f"repeat_{k + 1:02d}"
        write = ("all" if run_files == "all" else
                 "csv" if k == 0 and name in drawn else "summary")
        tasks.append(runner.Task(job.key, _run_one, (job.scenario, dict(job.overrides),
                                                     str(out), write, plot_format)))
    errors: list[tuple[Any, BaseException]] = []
    runner.run_tasks(tasks, lambda t, summary: done.__setitem__(t.key, summary),
                     lambda t, err: errors.append((t.key, err)), workers, scheduler,
                     f"{entry.name} runs", what=f"{entry.name}'s runs",
                     warm_up=warm_up_for([(t.args[0], t.args[1]) for t in tasks]))
    if errors:
        (name, k), err = errors[0]
        raise ReproduceError(f"{entry.path}: run {name!r}"
                             + (f" (repetition {k + 1})" if k else "") + f" failed: {err}"
                             ) from err
    if record is not None:
        for job in jobs:
            record.add(job, done[job.key])
    return merged_summaries(entry, {key: done[key] for key in done})


def merged_summaries(entry: Entry, done: dict[Any, Summary]
                     ) -> dict[str, Summary]:
    """Run name -> its summary from (run name, repetition) -> summary: a repeated run's
    medians with ``repeats`` (:func:`_merge_repeats`)."""
    result = {}
    for run in entry.runs:
        reps = [done[run.name, k] for k in range(run.repeat)]
        result[run.name] = reps[0] if len(reps) == 1 else _merge_repeats(reps)
    return result


def record_run_series(entry: Entry, out: Path, record: Record) -> None:
    """The series of the table runs the figures draw, from their results.csv under ``out``,
    added to ``record``."""
    scenarios = run_scenarios(entry)
    for name, figures in figure_runs(entry, FIGURE_KINDS).items():
        record_series(record, series_name("run", name), out / "runs" / slug(name), figures,
                      scenarios[name])


def figure_runs(entry: Entry, kinds: tuple[str, ...]) -> dict[str, list[Figure]]:
    """Run name -> the ``[[figures]]`` of ``kinds`` that draw it."""
    out: dict[str, list[Figure]] = {}
    for figure in entry.figures:
        if figure.kind in kinds:
            for run in figure.runs or entry.run_names():
                out.setdefault(run, []).append(figure)
    return out


def simulate(entry: Entry, out: Path, workers: int | None = None, seeds: int | None = None,
             rounding: bool = True, scheduler: str | None = None, plot_format: str = "png",
             previous: Record | None = None, build: str | None = None,
             run_files: str = "figures") -> Record:
    """Every simulation ``entry`` needs (its runs, sweeps and claims' members), through
    :mod:`cosim.run.runner`; the record of their results and of the series the figures draw.
    A job ``previous`` holds with the same specification is taken from it, not run again,
    where ``previous`` ran with this tree's simulation inputs, K, rounding path and ``build``
    (the catalog FMUs' native C builds where they exist, or every FMU's Python build; None:
    the entry's ``build``; the run folders under ``out`` then hold its files). ``run_files``:
    what each table run writes (:func:`run_entry`)."""
    k = claims_k(entry, seeds)
    build = build or entry.build
    digest = simulation_digest(entry.name, build) if shipped(entry) else ""
    record = Record(entry.name, digest, k, rounding, build)
    ours = (digest, k, rounding, build)
    if previous is not None and (previous.simulation, previous.seeds, previous.rounding,
                                 previous.build) != ours:
        theirs = (previous.simulation, previous.seeds, previous.rounding, previous.build)
        why = [what for what, a, b in zip(("simulation inputs", "K", "rounding path",
                                           "build"), theirs, ours, strict=True) if a != b]
        print(f"{entry.name}: the record under {out} has other {', '.join(why)}: nothing of it "
              "is reused", file=sys.stderr, flush=True)
        previous = None
    run_entry(entry, out, workers, scheduler, plot_format, record, previous, build,
              run_files)
    save(record, out)  # a checkpoint: an interrupted run resumes from here (--resume)
    record_run_series(entry, out, record)
    for job in sweep_jobs(entry, build):
        if known(previous, job):
            record.add(job, previous.result(job.kind, *job.key))
            continue
        grid = parse_grid(f"{k}={v}" for k, v in job.overrides.items())
        frame = run_sweep(job.scenario, grid, out / slug(job.key[0]), workers=workers,
                          scheduler=scheduler, plot=False)
        record.add(job, {"columns": list(frame.columns),
                         "rows": [[_plain(v) for v in row] for row in
                                  frame.astype(object).itertuples(index=False)]})
        save(record, out)  # a checkpoint
    if entry.claims:
        try:
            simulate_claims(entry, out, record, workers, scheduler, previous)
        except ValueError as err:
            raise ReproduceError(str(err)) from err
    return record


def _plain(value: Any) -> Any:
    """A JSON value of a frame cell: numpy scalars as Python ones, missing as None."""
    import pandas as pd

    if value is None or (not isinstance(value, str) and pd.isna(value)):
        return None
    return value.item() if isinstance(value, np.generic) else value


def claims_k(entry: Entry, seeds: int | None) -> int:
    """K of the claims' members: ``seeds``, else 20 or all the report seeds if fewer."""
    return seeds if seeds is not None else min(20, len(entry.ensemble.report_seeds))


def wanted_jobs(entry: Entry, k: int, rounding: bool, build: str = "python") -> list[Job]:
    """Every simulation the entry's tables, sweeps and claims at ``k`` members read, on
    ``build``."""
    return run_jobs(entry, build) + sweep_jobs(entry, build) + (
        member_jobs(entry, k, rounding, build) if entry.claims else [])
