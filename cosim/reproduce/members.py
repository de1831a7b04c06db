"""Run an entry's claims over their ensembles and write ``claims.csv`` / ``claims.md``.

Members of a claim's ensemble (K = ``--seeds``, the first K report seeds, except ``repeat``):

- ``disturbance``: member i sets ``[ensemble].seed_key`` to report seed i; without a seed key
  the plant has no random input and the ensemble is one (deterministic) run.
- ``mismatch``: member i is plant-mismatch sample i drawn from ``[ensemble].perturb``
  (:func:`cosim.run.perturbation.draw_samples`, seeded by ``[ensemble].perturb_seed``; the first K
  of the same sequence for every K), with report seed i where there is a seed key.
- ``repeat``: member i (i < ``[ensemble].repeats``) is the same nominal deterministic run
  (no seed, no draw), for metrics that vary run to run only through measurement (CPU and
  wall times). K is the entry's ``repeats``, independent of ``--seeds``. Pairs are repeat
  indices (repeat i of A with repeat i of B); the repeat jobs run first, in the order
  A0, B0, A1, B1, ... over every run of the repeat claims, so a drift of the machine's load
  meets both runs of a pair.

Every member of a ``disturbance`` or ``mismatch`` claim runs on the main path (path 0) and on
each perturbed floating-point path: path 1, the plants' numpy reference path
(``ATO_COSIM_NO_KERNELS=1`` in the worker, unless ``[ensemble].rounding_reference_path`` is
false or every FMU of the run is a native C build, which has none) with each
``[ensemble].rounding_perturb`` parameter scaled by 1 + 1e-12, and, where
``[ensemble].rounding_perturb_second`` names other parameters, path 2 with those scaled
(:meth:`cosim.reproduce.ensemble.Ensemble.rounding_paths`); a ``repeat`` claim has no such
rerun (its rounding-robust column reads "n/a": its metric is a measurement, not a result of the
floating-point path). The runs go through the shared runner (:mod:`cosim.run.runner`:
``--workers``, ``--scheduler``, one BLAS thread per worker, interrupts, progress on stderr).
"""

from __future__ import annotations

import dataclasses
import functools
import math
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from cosim.reproduce.builds import build_overrides, check_rounding_path, runs_a_python_build
from cosim.reproduce.claims import Claim, variant_runs
from cosim.reproduce.ensemble import ROUNDING_RELATIVE
from cosim.reproduce.entry import Entry, slug
from cosim.reproduce.record import Job as RecordJob
from cosim.reproduce.record import MemberKey, Overrides, Record, Summary, known, save, series_name
from cosim.reproduce.series import MEMBER_ROWS, record_series, run_scenarios
from cosim.run import runner
from cosim.run.master.pool import InstancePool
from cosim.run.perturbation import draw_samples, nominal_values, parse_perturb
from cosim.run.scenario import Scenario, load_scenario
from cosim.run.simulate import ensure_built, run_scenario
from cosim.run.sweep import warm_up_for

# s of wall time between two saves of the partial record while members finish: a kill loses at
# most this much of their work, and short members are not slowed by a save every few of them
CHECKPOINT_S = 10.0

Job = tuple[MemberKey, str, Overrides]  # the member, its scenario and overrides


def members(entry: Entry, ensemble: str, k: int) -> list[Overrides]:
    """Overrides of each member (before the run's own ``set``) of one ensemble kind."""
    ens = entry.ensemble
    if k < 1:
        raise ValueError(f"--seeds {k}: must be at least 1")
    if ensemble == "repeat":  # the entry's repeats, whatever --seeds
        if ens.repeats is None:
            raise ValueError(f"{entry.path}: [ensemble] repeats: not given, needed by a "
                             "'repeat' claim")
        return [{} for _ in range(ens.repeats)]
    if k > len(ens.report_seeds):
        raise ValueError(f"--seeds {k}: {entry.path} [ensemble] report_seeds has only "
                         f"{len(ens.report_seeds)} seeds")
    seeds = ens.report_seeds[:k]
    if ensemble == "disturbance":
        if ens.seed_key is None:
            return [{}]
        return [{ens.seed_key: s} for s in seeds]
    return [dict(d, **({ens.seed_key: s} if ens.seed_key else {}))
            for d, s in zip(_draws(entry, k), seeds, strict=True)]


def _draws(entry: Entry, k: int) -> list[dict[str, float]]:
    perts = parse_perturb(entry.ensemble.perturb)
    run = next(r for r in entry.runs
               if any(c.ensemble == "mismatch" and r.name in c.runs for c in entry.claims))
    nominals = nominal_values(run.scenario, [p.key for p in perts], run.overrides)
    return draw_samples(perts, nominals, k, entry.ensemble.perturb_seed)


def _rounding_overrides(entry: Entry, run: Any, base: Overrides, path: int,
                        nominals: dict[tuple[str, str], Any]) -> Overrides:
    """Perturbed path ``path``'s parameters (``base``'s value, else the run's, else the
    declared one) scaled by 1 + :data:`ROUNDING_RELATIVE`; ``nominals`` keeps the declared
    values read so far ((scenario, key) -> value), each read once."""
    out: Overrides = {}
    for key in entry.ensemble.rounding_keys(path):
        value = base.get(key, run.overrides.get(key))
        if value is None:
            if (run.scenario, key) not in nominals:
                # the start value of the scenario's own FMU (its Python build where it names
                # a catalog identifier): built first where missing, as on a fresh checkout
                # that runs the native builds
                ensure_built(load_scenario(run.scenario, run.overrides))
                nominals[run.scenario, key] = nominal_values(run.scenario, [key],
                                                             run.overrides)[key]
            value = nominals[run.scenario, key]
        if value is None:
            raise ValueError(f"{entry.path}: [ensemble] rounding perturbation {key!r}: no "
                             "nominal value to perturb")
        out[key] = float(value) * (1.0 + ROUNDING_RELATIVE)
    return out


def claim_cases(entry: Entry, k: int, rounding: bool = True
                ) -> list[tuple[str, Claim, list[str], bool, int]]:
    """(variant, claim, runs, with the rounding rerun, K) of every claim evaluation: the
    claims as written (variant "main", K = ``k``) and each ``[[variants]]`` replacing some of
    their runs (K = its ``seeds``, at most ``k``). A ``repeat`` claim never has the rounding
    rerun (its K is the entry's repeats, see :func:`members`)."""
    def rnd(claim: Claim, wanted: bool) -> bool:
        return wanted and claim.ensemble != "repeat"

    cases = [("main", c, list(c.runs), rnd(c, rounding), k) for c in entry.claims]
    for var in entry.variants:
        kv = min(k, var.seeds if var.seeds is not None else k)
        for claim in entry.claims:
            runs = variant_runs(claim, var)
            if runs is not None:
                cases.append((var.name, claim, runs, rnd(claim, rounding and var.rounding), kv))
    return cases


def claim_jobs(entry: Entry, k: int, rounding: bool = True, build: str = "python"
               ) -> list[Job]:
    """Every (run, ensemble, member, floating-point path) the claims and their variants need,
    once, with the
    ``build`` of the catalog FMUs (:func:`cosim.reproduce.builds.build_overrides`); the
    ``repeat`` members first, interleaved by repeat index (A0, B0, A1, B1, ...)."""
    runs = {r.name: r for r in entry.runs}
    paths = entry.ensemble.rounding_paths()
    builds = {name: build_overrides(run.scenario, run.overrides, build)
              for name, run in runs.items()}
    if rounding:
        check_rounding_path(entry, builds)
    jobs: dict[tuple[str, str, int, bool], Job] = {}
    cache: dict[tuple[str, int], list[Overrides]] = {}
    nominals: dict[tuple[str, str], Any] = {}  # declared values of the rounding paths
    for _var, claim, names, with_rnd, kc in claim_cases(entry, k, rounding):
        ens = claim.ensemble
        if (ens, kc) not in cache:
            cache[ens, kc] = members(entry, ens, kc)
        for name in names:
            run = runs[name]
            for i, member in enumerate(cache[ens, kc]):
                for path in (0, *paths) if with_rnd else (0,):
                    key = (name, ens, i, path)
                    overrides = {**builds[name], **member, **run.overrides}
                    if ens == "mismatch":  # the drawn plant wins over the run's nominal
                        overrides.update(member)
                    if path:
                        overrides.update(_rounding_overrides(entry, run, overrides, path,
                                                             nominals))
                    jobs.setdefault(key, (key, run.scenario, overrides))
    order = {name: j for j, name in enumerate(dict.fromkeys(key[0] for key in jobs))}
    repeats = sorted((key for key in jobs if key[1] == "repeat"),
                     key=lambda key: (key[2], order[key[0]]))
    return [jobs[key] for key in repeats] + [j for key, j in jobs.items()
                                             if key[1] != "repeat"]


# the FMU instances of this process's members, reset from one member to the next
MEMBER_INSTANCES = InstancePool()


def _run_member(scenario: str, overrides: Overrides, out_dir: str | None = None
                ) -> Summary:
    """One member in this (worker) process, on the instances of :data:`MEMBER_INSTANCES`;
    its summary with :func:`with_host`. With ``out_dir`` it records the scenario's
    ``[record]`` variables and writes them (results.csv, summary.json; no plot), else it
    records only what its summary reads (:func:`member_scenario`) and writes nothing."""
    before = host_load()
    sc = load_scenario(scenario, overrides)
    summary = run_scenario(sc if out_dir is not None else member_scenario(sc), out_dir=out_dir,
                           build=False, plot=False, pool=MEMBER_INSTANCES).summary
    return with_host(summary, before)


def member_scenario(sc: Scenario) -> Scenario:
    """``sc`` recording only the variables its ``[summary]`` names (and the infeasibility
    counters, :meth:`cosim.run.master.core.Master._recorded_refs`): every metric of a
    member, none of the scenario's other ``[record]`` variables."""
    return dataclasses.replace(sc, record=[])


def host_load() -> float:
    """The machine's 1-minute load average now (NaN where the system has none)."""
    import os

    try:
        return os.getloadavg()[0]
    except OSError:
        return math.nan


@functools.cache
def cpu_model() -> str:
    """The processor's name (``/proc/cpuinfo``'s model name on Linux, else the platform's)."""
    import platform

    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


@functools.cache
def _cores() -> int:
    """The machine's logical CPUs (0 where unknown)."""
    import os

    return os.cpu_count() or 0


def with_host(summary: Summary, load_before: float) -> Summary:
    """``summary`` with ``host``: where and under what load the run was measured (the CPU,
    its core count, the 1-minute load average before and after the run), which a timing
    claim's page states."""
    return {**summary, "host": {"cpu": cpu_model(), "cores": _cores(),
                                "load_before": load_before, "load_after": host_load()}}


def host_text(summaries: list[Summary | None]) -> str:
    """The machine and the range of its 1-minute load average over ``summaries`` (those
    with a ``host``), in words; "" where none has one."""
    hosts = [s["host"] for s in summaries if s and isinstance(s.get("host"), dict)]
    if not hosts:
        return ""
    loads = [h[k] for h in hosts for k in ("load_before", "load_after")
             if isinstance(h.get(k), (int, float)) and not math.isnan(h[k])]
    machines = sorted({f"{h.get('cpu', '?')}, {h.get('cores', '?')} cores" for h in hosts})
    text = "measured on " + "; ".join(machines)
    if loads:
        text += f", 1-minute load average {min(loads):.1f}-{max(loads):.1f} over the repeats"
    return text


def member_dir(out: Path, key: tuple[str, str, int, int]) -> Path:
    """Where a main-path member writes results.csv (``ensemble/<run>/<ensemble>_<i>``)."""
    return out / "ensemble" / slug(key[0]) / f"{key[1]}_{key[2] + 1:02d}"


ROUNDING_ENV = {"ATO_COSIM_NO_KERNELS": "1"}  # the plants' numpy reference path


def member_env(job: Job, reference_path: bool) -> dict[str, str]:
    """The environment ``job`` runs in: :data:`ROUNDING_ENV` on perturbed path 1 where
    ``reference_path`` and one of its FMUs runs a Python build; none for a run of native C
    builds alone, which have no numpy reference path (its path 1 is the parameter
    perturbation alone, :func:`cosim.reproduce.builds.check_rounding_path`), nor on the
    other paths."""
    key, scenario, overrides = job
    if key[3] != 1 or not reference_path or not runs_a_python_build(scenario, overrides):
        return {}
    return dict(ROUNDING_ENV)


def execute(jobs: list[Job], workers: int | None, label: str = "claims",
            scheduler: str | None = None, dirs: dict[Any, str] | None = None,
            reference_path: bool = True,
            on_result: Callable[[MemberKey, Summary | None], None] | None = None
            ) -> dict[MemberKey, Summary | None]:
    """Run the jobs with :func:`cosim.run.runner.run_tasks`: the main path and the perturbed
    paths in one pool of workers, each worker running its members on the same FMU instances
    (:data:`MEMBER_INSTANCES`), except the members whose :func:`member_env` is
    ``ATO_COSIM_NO_KERNELS=1`` (path 1 with a Python build, unless ``reference_path`` is
    false), in workers of their own started with it, after the others; a failed run gives
    None (its metrics are missing).
    ``dirs``: job key -> folder for the run's results (others write none);
    ``on_result(key, summary)`` as each ends."""
    dirs = dirs or {}
    out: dict[MemberKey, Summary | None] = {}
    progress = runner.Progress(len(jobs), label)

    def finished(task: runner.Task, summary: Any) -> None:
        out[task.key] = summary
        if on_result is not None:
            on_result(task.key, summary)

    def failed(task: runner.Task, err: BaseException) -> None:
        print(f"{label}: {task.key} failed: {err}", file=sys.stderr)
        out[task.key] = None

    by_env: dict[bool, list[Job]] = {}  # the paths of one environment share their workers
    for job in sorted(jobs, key=lambda job: job[0][3]):
        by_env.setdefault(bool(member_env(job, reference_path)), []).append(job)
    for reference, group in sorted(by_env.items()):
        tasks = [runner.Task(key, _run_member, (sc, ov, dirs.get(key)))
                 for key, sc, ov in group]
        runner.run_tasks(tasks, finished, failed, workers, scheduler, label,
                         env=ROUNDING_ENV if reference else None, progress=progress,
                         warm_up=warm_up_for([(sc, ov) for _k, sc, ov in jobs]),
                         what="the claims' runs")
    return out


def member_jobs(entry: Entry, k: int, rounding: bool = True, build: str = "python"
                ) -> list[RecordJob]:
    """:func:`claim_jobs` as record jobs, with the environment each ran in
    (:func:`member_env`)."""
    return [RecordJob("member", *job, member_env(job, entry.ensemble.rounding_reference_path))
            for job in claim_jobs(entry, k, rounding, build)]


def _banded(entry: Entry) -> set[str]:
    """Runs drawn by an overlay or panels figure: their members keep their series."""
    return {r for f in entry.figures if f.line_kind() for r in f.runs or entry.run_names()}


def simulate_claims(entry: Entry, out: Path, record: Record, workers: int | None = None,
                    scheduler: str | None = None, previous: Record | None = None) -> None:
    """Run the claims' members (K and rounding path of ``record``) and add their summaries to
    ``record``, with the series of the members the ensemble figures draw; a member
    ``previous`` holds with the same specification is taken from it, not run again."""
    wanted = member_jobs(entry, record.seeds, record.rounding, record.build)
    reuse = {job.key for job in wanted if known(previous, job)}
    jobs = [j for j in claim_jobs(entry, record.seeds, record.rounding, record.build)
            if j[0] not in reuse]
    built: set[str] = set()
    for _key, scenario, overrides in jobs:  # bad overrides fail before anything runs
        sc = load_scenario(scenario, overrides)
        if scenario not in built:
            ensure_built(sc)
            built.add(scenario)
    banded = _banded(entry)
    dirs = {key: str(member_dir(out, key)) for key, _sc, _ov in jobs
            if key[0] in banded and key[1] == "disturbance" and not key[3]}
    by_key = {job.key: job for job in wanted}
    for job in wanted:  # the reused members first: a checkpoint keeps them
        if job.key in reuse:
            record.add(job, previous.result(job.kind, *job.key))
    saved = time.monotonic()

    def checkpoint(key: MemberKey, summary: Summary | None) -> None:
        nonlocal saved
        if summary is not None:  # a failed member is run again on --resume
            record.add(by_key[key], summary)
        if time.monotonic() - saved >= CHECKPOINT_S:
            save(record, out)  # an interrupted run resumes from here (--resume)
            saved = time.monotonic()

    summaries = execute(jobs, workers, f"{entry.name} claims", scheduler, dirs,
                        entry.ensemble.rounding_reference_path, checkpoint)
    for job in wanted:  # a failed member: no result (the others are in from checkpoint)
        if job.key not in reuse and summaries.get(job.key) is None:
            record.add(job, None)
    record_member_series(entry, out, record)


def record_member_series(entry: Entry, out: Path, record: Record) -> None:
    """The series of the members the ensemble figures draw (main path, disturbance, banded
    runs) from their results.csv under ``out``, added to ``record`` (thinned to
    :data:`cosim.reproduce.series.MEMBER_ROWS` rows)."""
    scenarios = run_scenarios(entry)
    banded = _banded(entry)
    lines = [f for f in entry.figures if f.line_kind()]
    for ident, job in record.jobs.items():
        key = job.key
        if (job.kind == "member" and key[0] in banded and key[1] == "disturbance"
                and not key[3] and record.results[ident] is not None):
            record_series(record, series_name("member", key[0], key[2]),
                          member_dir(out, key),
                          [f for f in lines if f.runs is None or key[0] in f.runs],
                          scenarios[key[0]], scalars=False, max_rows=MEMBER_ROWS)
