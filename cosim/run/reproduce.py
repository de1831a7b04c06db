"""Paper reproductions as data plus one command: ``cosim reproduce SEED`` / ``cosim reproduce all``.

Each paper has an entry ``scenarios/reproduce/<name>.toml`` (the paper's numbers and tolerances
live there, not in code)::

    title = "Author et al. (year): ..."
    citation = "Authors: title. Journal vol(no), year."   # optional, shown under the title
    [[statements]]                 # each assertion of the paper (its results and conclusions)
    text = "RSMPC switches the command far less often than RMPC"
    where = "sec. 4, Fig. 11"      # optional: default, the sources of its claims
    claims = ["rsmpc_fewer_switches_n10"]   # the claims that test it, or instead:
    untestable = "why it cannot be tested here"
    notes = "why our figures differ from the paper's"     # optional, markdown
    table = "table2"               # optional: the table's file name (default "table")
    set = { "plant.disturbance_amplitude" = 0.02 }   # optional: overrides of every run and
                                   # sweep (the entry's disturbance); a run's own set wins
    [[runs]]                       # one table row per run
    name = "RMPC N=5"
    scenario = "stop_rmpc"
    set = { "controller.N" = 5 }   # optional overrides (as --set)
    repeat = 10                    # optional: run it 10 times; numeric metrics are shown as
                                   # "median [min, max]" (e.g. computation times); the first
                                   # repetition's results feed the figures
    [[metrics]]                    # table columns: summary.json keys ('.' for nested keys)
    key = "stop_error_m"
    label = "stop error (m)"
    ratio_to = "PID"               # optional: also a column ours / that run's (medians), and
                                   # the paper's ratio where the paper gives both figures
    [[paper]]                      # the paper's figure for (run, metric)
    run = "PID"
    metric = "stop_error_m"
    value = 0.2898                 # the paper's number (shown), and/or
    range = [-0.5, 0.5]            # the band the paper requires (shown when there is no value)
    tolerance = 0.5                # optional verdict: |ours - value| <= tolerance, or ours in range
    source = "sec. 4.1"
    [[derived]]                    # optional: a figure computed from two runs' summaries
    name = "eco saving, net energy"
    kind = "saving_percent"        # 100 (1 - run / baseline); the only kind so far
    metric = "energy_net_mj"       # a summary key ('.' for nested keys)
    run = "Eco"                    # [[runs]] names
    baseline = "Conventional"
    value = 17.7                   # optional, as in [[paper]]: value, range, tolerance, source
    range = [15.0, 22.0]
    source = "sec. 3.1 text"
    [[rankings]]                   # optional: the runs ordered by a metric, lowest first
    name = "main rows"             # shown with the ranking
    metric = "unit_mse_kmh2"       # a [[metrics]] key
    runs = ["ISMPC", "ISMC", "MFAC", "GPC"]   # [[runs]] names
    paper = ["ISMPC", "ISMC", "MFAC", "GPC"]  # optional: the paper's order of the same runs;
                                   # the verdict names the pairs ours orders the other way
    [[sweeps]]                     # optional: a cosim sweep (sweep.csv, sweep.png)
    name = "fig11"
    scenarios = ["stop_rmpc", "stop_rsmpc"]
    grid = { "controller.N" = "3..15" }
    labels = { stop_rmpc = "RMPC" }  # optional: the legend's name of a scenario's series
                                   # (default: the scenario's description)
    [[figures]]                    # drawn from the runs' results.csv
    file = "fig_speed.png"
    title = "Speed against position"
    kind = "overlay"               # overlay (one line per run) | panels (one panel per run)
    x = "plant.s"                  # a recorded column or "time"
    y = ["plant.v"]                # columns; "plant.v[*]" with y_reduce = "mean": their mean
    y_minus = "controller.v_ref"   # optional: plot y - this column (an error)
    y_scale = 3.6                  # optional factor (m/s -> km/h)
    ylabel = "speed (km/h)"
    runs = ["PID", "MPC"]          # optional, default all
    limit_ref = "controller.v_ref" # optional, for an error (y_minus): the zero-error reference
    limit_kmh = 2.0                # and the +-allowance of that reference speed drawn, as in
    limit_below_kmh = 30.0         # speed_classes (y_scale 3.6: km/h)
    limit_fraction = 0.02
    xlim = [395.0, 401.0]          # optional: the axes' x / y range in the drawn units (a
    ylim = [0.0, 10.0]             # zoom), and a shaded x band [lo, hi] with its label:
    band_x = [399.5, 400.5, "stop window +-50 cm"]
    [[figures]]                    # graded speed error: the max |error| of
    file = "fig8.png"              # each run per class of the reference speed, with the limit
    kind = "speed_classes"         # |e| <= max(limit_kmh if v <= limit_below_kmh, fraction v)
    ref = "controller.v_ref"       # the reference speed column (classes are of it)
    y = ["plant.v[1]"]             # speeds; error = y - ref; y_scale converts both (3.6: km/h)
    y_scale = 3.6
    classes = [0, 30, 50, 100]     # class edges (km/h): (0, 30], (30, 50], (50, 100]
    limit_kmh = 2.0                # e.g. 2 km/h at or below 30 km/h, 2 % above
    limit_below_kmh = 30.0
    limit_fraction = 0.02
    paper = "what the paper reports"   # optional, shown under the figure

    [ensemble]                     # optional (claims): how a run is varied over seeds
    seed_key = "plant.disturbance_seed"   # override key taking the seed (absent: no random
                                   # input; a "disturbance" claim is then one run)
    report_seeds = "1..20"         # --seeds K takes the first K (default 20)
    calibration_seeds = "101..110" # tuning only; disjoint from report_seeds (checked)
    perturb = ["plant.mass=+-10%"] # mismatch distribution (as --perturb), for "mismatch"
    perturb_seed = 1               # optional: seed of the mismatch draws (default 0)
    rounding_perturb = ["plant.v0"]  # optional: parameters scaled by 1 + 1e-12 on the
                                   # perturbed floating-point rerun (besides the plants'
                                   # numpy reference path, ATO_COSIM_NO_KERNELS=1)
    rounding_reference_path = true # optional: false keeps the compiled kernels on the rerun
                                   # (then rounding_perturb alone perturbs it)
    repeats = 10                   # "repeat" claims: repetitions of the nominal run (K of
                                   # those claims, whatever --seeds; no rounding rerun)
    [[claims]]                     # a claim of the paper, tested over the ensemble
    id = "ismpc_mse_below_ismc"    # unique, [a-z0-9_]
    source = "Table 2"
    text = "ISMPC has a lower MSE than ISMC"
    paper = "0.052 vs 0.161 (km/h)^2"   # the paper's value(s), as text
    metric = "unit_mse_kmh2"       # a summary key ('.' for nested keys; a bool counts 1 / 0)
    kind = "less"                  # less | greater: runs[0] vs runs[1], paired by member;
                                   # below | above: runs[0] against threshold;
                                   # inside: runs[0]'s median within range
    runs = ["ISMPC", "ISMC"]
    threshold = 0.2                # below / above
    range = [-0.5, 0.5]            # inside
    quantifier = "typical"         # every | share | typical (cosim.run.claims; default:
                                   # every for below/above/inside, typical for less/greater)
    share = 0.9                    # with quantifier "share": at least this fraction of runs
    transform = "abs"              # optional: the metric's absolute value per member
    ensemble = "disturbance"       # disturbance (report seeds) | mismatch (perturb samples)
                                   # | repeat (the nominal run [ensemble].repeats times,
                                   # paired by repeat index: CPU / wall time claims)
    origin = "paper"               # paper | ours | sanity (a check of the setup)
    each.law = [{ key = "rmpc", name = "RMPC" }, { key = "rsmpc", name = "RSMPC" }]
    each.n = ["3", "10", "15"]     # optional: a claim family, one claim per combination
                                   # (cross product); "{law.name} N={n}" in any string, the
                                   # id included (cosim.run.claims.expand_families)
    [[variants]]                   # optional: every claim again with some runs replaced (an
    name = "white"                 # alternative reading, a mechanism removed); claims.md
    text = "the paper's white noise"  # gets a verdict per claim and variant, variants.csv
    replace = { "ISMPC" = "ISMPC white", "ISMC" = "ISMC white" }   # [[runs]] names
    rounding = true                # optional (default true): the perturbed floating-point
                                   # rerun too, as the main claims get it
    seeds = 5                      # optional: the first 5 report seeds (at most --seeds)

The claims are evaluated by :mod:`cosim.run.claims` (statistics and verdicts) over the runs
of :mod:`cosim.run.ensemble` (members, perturbed floating-point rerun), which write
``claims.csv`` and ``claims.md``; ``table.md`` includes the claims table.

The command has two halves. :func:`simulate` runs every job the entry needs (the table runs,
the sweeps, the claims' members; in parallel processes), writes each run's results under
``runs/`` and returns their :class:`cosim.run.record.Record`, kept in ``record/``.
:func:`evaluate` makes everything else from that record and the entry alone: ``table.md`` and
``table.csv`` (or the entry's ``table`` name; the verdicts and the claims table first, then
ours beside the paper's, with the verdict where a tolerance is given; derived figures and
rankings follow the table, and are rows of ``table.csv`` with ``metric = "<kind>:<metric>"``
/ ``"rank:<metric>"``), the statements table, the sweeps' tables and figures and the figures
(:mod:`cosim.run.figures`). :func:`redraw_entry` (``--redraw``) is the second half alone.
``all`` runs every entry and writes one ``REPRODUCTION.md``.
"""

from __future__ import annotations

import math
import re
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from cosim.run.claims import (
    ClaimsError,
    Ensemble,
    check_claims,
    check_ensemble,
    check_statements,
    check_variants,
    number,
    ratio_ci,
)
from cosim.run.figures import (
    draw_figure,
    figure_columns,
    legend_outside,
    reference_curve,  # noqa: F401 - the run plot (cosim.run.results) imports it from here
    speed_class_errors,
)
from cosim.run.provenance import INPUTS_FILE, entry_digest, simulation_digest
from cosim.run.record import (
    Job,
    Record,
    RecordError,
    check_jobs,
    known,
    load,
    read_csv,
    save,
    series_name,
)
from cosim.run.results import PLOT_DPI
from cosim.run.scenario import SCENARIO_DIR

try:
    import tomllib
except ModuleNotFoundError:  # Python < 3.11
    import tomli as tomllib  # type: ignore[no-redef]

REPRODUCE_DIR = SCENARIO_DIR / "reproduce"

# "ensemble" and "claims": the claims schema (docs of the claims framework), read there
_ENTRY_KEYS = {"title", "citation", "statements", "notes", "table", "set", "runs", "metrics",
               "paper", "derived", "rankings", "sweeps", "figures", "ensemble", "claims",
               "variants"}
_RANKING_KEYS = {"name", "metric", "runs", "paper"}
_DERIVED_KEYS = {"name", "kind", "metric", "run", "baseline", "value", "range", "tolerance",
                 "source"}
DERIVED_KINDS = ("saving_percent",)
_RUN_KEYS = {"name", "scenario", "set", "repeat"}
_METRIC_KEYS = {"key", "label", "ratio_to"}
_PAPER_KEYS = {"run", "metric", "value", "range", "tolerance", "source"}
_SWEEP_KEYS = {"name", "scenarios", "grid", "labels"}
_FIGURE_KEYS = {"file", "title", "kind", "x", "y", "y_scale", "ylabel", "xlabel", "runs",
                "y_reduce", "y_minus", "limit_ref", "limit_kmh", "limit_below_kmh",
                "limit_fraction", "xlim", "ylim", "band_x"}
_CLASS_KEYS = {"file", "title", "kind", "y", "y_scale", "ylabel", "runs", "ref", "classes",
               "limit_kmh", "limit_below_kmh", "limit_fraction", "paper"}
FIGURE_KINDS = ("overlay", "panels", "speed_classes")


class ReproduceError(ValueError):
    """A reproduction entry that cannot be used (the message names the file and key)."""


@dataclass
class Entry:
    name: str
    path: Path
    title: str
    runs: list[dict[str, Any]]
    metrics: list[dict[str, Any]]
    paper: list[dict[str, Any]] = field(default_factory=list)
    derived: list[dict[str, Any]] = field(default_factory=list)
    sweeps: list[dict[str, Any]] = field(default_factory=list)
    figures: list[dict[str, Any]] = field(default_factory=list)
    notes: str = ""
    rankings: list[dict[str, Any]] = field(default_factory=list)
    table: str = "table"
    ensemble: Ensemble = field(default_factory=Ensemble)
    claims: list[dict[str, Any]] = field(default_factory=list)
    variants: list[dict[str, Any]] = field(default_factory=list)
    citation: str = ""
    statements: list[dict[str, Any]] = field(default_factory=list)


def entry_names() -> list[str]:
    return sorted(p.stem for p in REPRODUCE_DIR.glob("*.toml"))


def _check_keys(where: str, table: dict[str, Any], allowed: set[str],
                required: tuple[str, ...]) -> None:
    unknown = sorted(set(table) - allowed)
    if unknown:
        raise ReproduceError(f"{where}: unknown key(s) {unknown} (allowed: {sorted(allowed)})")
    missing = [k for k in required if k not in table]
    if missing:
        raise ReproduceError(f"{where}: missing key(s) {missing}")


def load_entry(name: str | Path) -> Entry:
    """Read and check an entry by name (its file in ``scenarios/reproduce/`` without ``.toml``)
    or path."""
    path = Path(name)
    if not path.suffix:
        path = REPRODUCE_DIR / f"{name}.toml"
    if not path.is_file():
        raise ReproduceError(f"no reproduction entry {str(name)!r} (known: {entry_names()})")
    try:
        data = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as err:
        raise ReproduceError(f"{path}: not valid TOML: {err}") from err
    _check_keys(str(path), data, _ENTRY_KEYS, ("title", "runs"))
    table = data.get("table", "table")
    if not (isinstance(table, str) and re.fullmatch(r"[A-Za-z0-9_-]+", table)):
        raise ReproduceError(f"{path}: table = {table!r} must be a file name without folder or "
                             "suffix (letters, digits, '_', '-')")
    common = data.get("set", {})
    if not isinstance(common, dict):
        raise ReproduceError(f"{path}: set = {common!r} must be a table of overrides")
    runs = data["runs"]
    for i, run in enumerate(runs):
        _check_keys(f"{path}: [[runs]] #{i + 1}", run, _RUN_KEYS, ("name", "scenario"))
        if common:
            run["set"] = {**common, **run.get("set", {})}
        rep = run.get("repeat", 1)
        if isinstance(rep, bool) or not isinstance(rep, int) or rep < 1:
            raise ReproduceError(f"{path}: [[runs]] #{i + 1}: repeat = {rep!r} must be an "
                                 "integer >= 1")
    names = [r["name"] for r in runs]
    if len(set(names)) != len(names):
        raise ReproduceError(f"{path}: [[runs]] names repeat: {names}")
    metrics = data.get("metrics", [])
    for i, metric in enumerate(metrics):
        _check_keys(f"{path}: [[metrics]] #{i + 1}", metric, _METRIC_KEYS, ("key",))
        if "ratio_to" in metric and metric["ratio_to"] not in names:
            raise ReproduceError(f"{path}: [[metrics]] #{i + 1}: ratio_to "
                                 f"{metric['ratio_to']!r} is not one of {names}")
    keys = {m["key"] for m in metrics}
    for i, ref in enumerate(data.get("paper", [])):
        where = f"{path}: [[paper]] #{i + 1}"
        _check_keys(where, ref, _PAPER_KEYS, ("run", "metric"))
        if "value" not in ref and "range" not in ref:
            raise ReproduceError(f"{where}: needs a value or a range")
        if "range" in ref and not (isinstance(ref["range"], list) and len(ref["range"]) == 2
                                   and ref["range"][0] <= ref["range"][1]):
            raise ReproduceError(f"{where}: range {ref.get('range')!r} must be [low, high]")
        if "tolerance" in ref and "value" not in ref:
            raise ReproduceError(f"{where}: a tolerance needs a value")
        if ref["run"] not in names:
            raise ReproduceError(f"{where}: run {ref['run']!r} is not one of {names}")
        if ref["metric"] not in keys:
            raise ReproduceError(f"{where}: metric {ref['metric']!r} is not in [[metrics]]")
    for i, der in enumerate(data.get("derived", [])):
        where = f"{path}: [[derived]] #{i + 1}"
        _check_keys(where, der, _DERIVED_KEYS, ("name", "kind", "metric", "run", "baseline"))
        if der["kind"] not in DERIVED_KINDS:
            raise ReproduceError(f"{where}: kind {der['kind']!r} (known: {DERIVED_KINDS})")
        for key in ("run", "baseline"):
            if der[key] not in names:
                raise ReproduceError(f"{where}: {key} {der[key]!r} is not one of {names}")
    for i, rank in enumerate(data.get("rankings", [])):
        where = f"{path}: [[rankings]] #{i + 1}"
        _check_keys(where, rank, _RANKING_KEYS, ("metric", "runs"))
        if rank["metric"] not in keys:
            raise ReproduceError(f"{where}: metric {rank['metric']!r} is not in [[metrics]]")
        unknown_runs = sorted(set(rank["runs"]) - set(names))
        if unknown_runs or len(set(rank["runs"])) != len(rank["runs"]) or not rank["runs"]:
            raise ReproduceError(f"{where}: runs {rank['runs']!r} must be distinct [[runs]] "
                                 f"names (unknown: {unknown_runs})")
        if "paper" in rank and sorted(rank["paper"]) != sorted(rank["runs"]):
            raise ReproduceError(f"{where}: paper {rank['paper']!r} must order the same runs "
                                 f"as runs {rank['runs']!r}")
    for i, sweep in enumerate(data.get("sweeps", [])):
        _check_keys(f"{path}: [[sweeps]] #{i + 1}", sweep, _SWEEP_KEYS,
                    ("name", "scenarios", "grid"))
        unnamed = sorted(set(sweep.get("labels", {})) - {Path(s).stem for s in sweep["scenarios"]})
        if unnamed:
            raise ReproduceError(f"{path}: [[sweeps]] #{i + 1}: labels name scenarios "
                                 f"{unnamed} that are not in its scenarios "
                                 f"{sweep['scenarios']!r}")
        # the sweep's own keys first (the first is its figure's x axis), then the entry's
        sweep["grid"] = {**sweep["grid"],
                         **{k: v for k, v in common.items() if k not in sweep["grid"]}}
    for i, fig in enumerate(data.get("figures", [])):
        where = f"{path}: [[figures]] #{i + 1}"
        if fig.get("kind", "overlay") not in FIGURE_KINDS:
            raise ReproduceError(f"{where}: kind {fig['kind']!r} (known: {FIGURE_KINDS})")
        if fig.get("kind") == "speed_classes":
            _check_keys(where, fig, _CLASS_KEYS, ("file", "y", "ref", "classes", "limit_kmh",
                                                  "limit_below_kmh", "limit_fraction"))
            edges = fig["classes"]
            if len(edges) < 2 or any(b <= a for a, b in zip(edges[:-1], edges[1:],
                                                            strict=True)):
                raise ReproduceError(f"{where}: classes {edges!r} must be increasing edges")
        else:
            _check_keys(where, fig, _FIGURE_KEYS, ("file", "x", "y"))
            if fig.get("y_reduce", "mean") != "mean":
                raise ReproduceError(f"{where}: y_reduce {fig['y_reduce']!r} (known: 'mean')")
            for key in ("xlim", "ylim", "band_x"):
                value = fig.get(key)
                span = value[:2] if isinstance(value, list) else None
                if value is not None and not (
                        span is not None and len(span) == 2
                        and all(isinstance(v, (int, float)) and not isinstance(v, bool)
                                for v in span) and span[0] < span[1]
                        and (key == "band_x" and len(value) in (2, 3) or len(value) == 2)):
                    raise ReproduceError(f"{where}: {key} = {value!r}: expected [low, high]"
                                         + (" or [low, high, label]" if key == "band_x"
                                            else "") + " with low < high")
        unknown_runs = sorted(set(fig.get("runs", names)) - set(names))
        if unknown_runs:
            raise ReproduceError(f"{where}: runs {unknown_runs} are not in [[runs]]")
    try:
        ensemble = check_ensemble(str(path), data.get("ensemble"))
        claims = check_claims(str(path), data.get("claims", []), names, ensemble)
        variants = check_variants(str(path), data.get("variants", []), names)
        statements = check_statements(str(path), data.get("statements", []),
                                      [c["id"] for c in claims])
    except ClaimsError as err:
        raise ReproduceError(str(err)) from err
    return Entry(path.stem, path, data["title"], runs, metrics, data.get("paper", []),
                 data.get("derived", []), data.get("sweeps", []), data.get("figures", []),
                 data.get("notes", ""), data.get("rankings", []), table, ensemble, claims,
                 variants, str(data.get("citation", "")), statements)


def slug(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9]+", "_", name).strip("_").lower()


def summary_value(summary: dict[str, Any], key: str) -> Any:
    """``summary["a"]["b"]`` for ``key = "a.b"``; None where absent."""
    value: Any = summary
    for part in key.split("."):
        if not isinstance(value, dict) or part not in value:
            return None
        value = value[part]
    return value


def _run_one(scenario: str, overrides: dict[str, Any], out_dir: str,
             plot_format: str = "png") -> dict[str, Any]:
    from cosim.run.master import run_scenario

    result = run_scenario(scenario, overrides=overrides, out_dir=out_dir, build=False,
                          plot_format=plot_format)
    return result.summary


def _merge_repeats(summaries: list[dict[str, Any]]) -> dict[str, Any]:
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


def table_seed(entry: Entry) -> dict[str, int]:
    """The random input of the table's single runs: ``[ensemble] seed_key`` at the first
    report seed (so a single run is member 1 of the claims' ensemble), or nothing where the
    entry has no random input."""
    key = entry.ensemble.seed_key
    return {key: entry.ensemble.report_seeds[0]} if key and entry.ensemble.report_seeds else {}


def run_jobs(entry: Entry) -> list[Job]:
    """The table runs' simulations: one job per run and repetition, at :func:`table_seed`
    unless the run sets its seed itself."""
    seed = table_seed(entry)
    return [Job("run", (run["name"], k), run["scenario"], {**seed, **run.get("set", {})})
            for run in entry.runs for k in range(int(run.get("repeat", 1)))]


def sweep_jobs(entry: Entry) -> list[Job]:
    """One job per ``[[sweeps]]`` entry (its scenarios and grid)."""
    return [Job("sweep", (sweep["name"],), list(sweep["scenarios"]), dict(sweep["grid"]))
            for sweep in entry.sweeps]


def run_entry(entry: Entry, out_dir: Path, workers: int | None = None,
              scheduler: str | None = None, plot_format: str = "png",
              record: Record | None = None, previous: Record | None = None
              ) -> dict[str, dict[str, Any]]:
    """Run every run of ``entry`` with :func:`cosim.run.runner.run_tasks` (``workers``
    processes or the Dask ``scheduler``; a run with ``repeat = k`` k times, repetitions 2..
    under ``runs/<run>/repeat_NN``); returns run name -> summary (medians and ``repeats`` for
    a repeated run), each repetition's summary added to ``record``; a run ``previous`` holds
    with the same specification is taken from it, not run again. A failed run raises
    :class:`ReproduceError` naming it, after the others finished."""
    from cosim.run import runner
    from cosim.run.master import ensure_built
    from cosim.run.scenario import load_scenario
    from cosim.run.sweep import warm_up_for

    for run in entry.runs:  # bad overrides fail here, before anything runs; build once
        ensure_built(load_scenario(run["scenario"], run.get("set", {})))
    jobs = run_jobs(entry)
    tasks = []
    done: dict[Any, dict[str, Any]] = {}
    for job in jobs:
        if previous is not None and known(previous, job):
            done[job.key] = previous.result(job.kind, *job.key)
            continue
        name, k = job.key
        base = out_dir / "runs" / slug(name)
        out = base if k == 0 else base / f"repeat_{k + 1:02d}"
        tasks.append(runner.Task(job.key, _run_one,
                                 (job.scenario, dict(job.overrides), str(out), plot_format)))
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


def merged_summaries(entry: Entry, done: dict[Any, dict[str, Any]]
                     ) -> dict[str, dict[str, Any]]:
    """Run name -> its summary from (run name, repetition) -> summary: a repeated run's
    medians with ``repeats`` (:func:`_merge_repeats`)."""
    result = {}
    for run in entry.runs:
        reps = [done[run["name"], k] for k in range(int(run.get("repeat", 1)))]
        result[run["name"]] = reps[0] if len(reps) == 1 else _merge_repeats(reps)
    return result


def _row(cells: list[str]) -> str:
    """A markdown table row; a ``|`` inside a cell (``max |e|``) is escaped."""
    return "| " + " | ".join(str(c).replace("|", "\\|") for c in cells) + " |"


def _fmt(value: Any) -> str:
    if value is None:
        return "-"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float):
        return number(value)
    return str(value)


def table_rows(entry: Entry, summaries: dict[str, dict[str, Any]]) -> list[dict[str, Any]]:
    """Long format: one row per (run, metric) with ours, the paper's and the verdict."""
    refs = {(r["run"], r["metric"]): r for r in entry.paper}
    rows = []
    for run in entry.runs:
        for metric in entry.metrics:
            ours = summary_value(summaries[run["name"]], metric["key"])
            ref = refs.get((run["name"], metric["key"]))
            ref = ref or {}
            band = ref.get("range")
            spread = repeat_spread(summaries[run["name"]], metric["key"])
            row = {"run": run["name"], "metric": metric["key"], "ours": ours,
                   "ours_min": spread[0] if spread else None,
                   "ours_max": spread[1] if spread else None,
                   "repeats": spread[2] if spread else 1,
                   "paper": ref.get("value"), "paper_range": band,
                   "tolerance": ref.get("tolerance"), "source": ref.get("source", "")}
            base_run = metric.get("ratio_to")
            if base_run is not None:
                base = summary_value(summaries[base_run], metric["key"])
                base_ref = refs.get((base_run, metric["key"]), {}).get("value")
                row["ratio"] = (float(ours) / float(base) if ours is not None and base
                                else None)
                # repeated runs: the ratio of medians with its bootstrap CI
                ours_reps = repeat_values(summaries[run["name"]], metric["key"])
                base_reps = repeat_values(summaries[base_run], metric["key"])
                row["ratio_ci_low"] = row["ratio_ci_high"] = None
                if ours_reps is not None and base_reps is not None:
                    _, lo, hi = ratio_ci(np.array(ours_reps), np.array(base_reps))
                    if np.isfinite(lo) and np.isfinite(hi):
                        row["ratio_ci_low"], row["ratio_ci_high"] = lo, hi
                row["paper_ratio"] = (float(ref["value"]) / float(base_ref)
                                      if ref.get("value") is not None and base_ref else None)
            within = None
            if ours is not None and band is not None:
                within = band[0] <= float(ours) <= band[1]
            if ours is not None and row["tolerance"] is not None:
                close = abs(float(ours) - float(ref["value"])) <= row["tolerance"]
                within = close if within is None else within and close
            row["within"] = within
            rows.append(row)
    return rows


def derived_rows(entry: Entry, summaries: dict[str, dict[str, Any]]) -> list[dict[str, Any]]:
    """One row per ``[[derived]]`` figure, in the long format of :func:`table_rows`."""
    rows = []
    for der in entry.derived:
        ours = None
        run = summary_value(summaries[der["run"]], der["metric"])
        base = summary_value(summaries[der["baseline"]], der["metric"])
        if run is not None and base not in (None, 0):
            ours = 100.0 * (1.0 - float(run) / float(base))  # saving_percent
        band = der.get("range")
        within = None
        if ours is not None and band is not None:
            within = band[0] <= ours <= band[1]
        if ours is not None and der.get("tolerance") is not None:
            close = abs(ours - float(der["value"])) <= der["tolerance"]
            within = close if within is None else within and close
        rows.append({"run": der["name"], "metric": f"{der['kind']}:{der['metric']}",
                     "ours": ours, "paper": der.get("value"), "paper_range": band,
                     "tolerance": der.get("tolerance"), "source": der.get("source", ""),
                     "within": within,
                     "of": f"{der['run']} against {der['baseline']}"})
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
        ours = sorted(rank["runs"], key=lambda run, m=rank["metric"]: value(run, m))
        paper = rank.get("paper")
        swapped = []
        if paper is not None:
            place = {run: i for i, run in enumerate(ours)}
            swapped = [f"{b} < {a}" for i, a in enumerate(paper) for b in paper[i + 1:]
                       if place[b] < place[a]]
        label = next(m.get("label", m["key"]) for m in entry.metrics
                     if m["key"] == rank["metric"])
        rows.append({"run": rank.get("name", ""), "metric": f"rank:{rank['metric']}",
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
        lines.append(_row([r["label"], r["run"], r["ours"] + mark, _fmt(r["paper"]),
                           r["source"] or "-"]))
    return "\n".join(lines)


def derived_markdown(rows: list[dict[str, Any]]) -> str:
    lines = ["| derived figure | of | ours | paper | source |", "| --- | --- | --- | --- | --- |"]
    for r in rows:
        mark = "" if r["within"] is None else (" ✓" if r["within"] else " ✗")
        paper = _fmt(r["paper"])
        if r["paper_range"] is not None:
            band = f"in [{_fmt(r['paper_range'][0])}, {_fmt(r['paper_range'][1])}]"
            paper = band if r["paper"] is None else f"{paper} ({band})"
        lines.append(_row([f"{r['run']} ({r['metric']})", r["of"], _fmt(r["ours"]) + mark,
                           paper, r["source"]]))
    return "\n".join(lines)


TABLE_COLUMNS = 9  # at most this many columns in one markdown table of a paper page


def table_markdown(entry: Entry, rows: list[dict[str, Any]]) -> str:
    """A row per run; per metric an "ours" column and a "paper" column (left out where the
    paper gives no value for any run), and with ``ratio_to`` the ratio and the paper's. When
    the columns exceed :data:`TABLE_COLUMNS` the metrics are split over several tables, each
    repeating the run column (a metric's columns stay together)."""
    by = {(r["run"], r["metric"]): r for r in rows}
    runs = [run["name"] for run in entry.runs]
    groups: list[list[tuple[str, list[str]]]] = []  # per metric: (header, cells per run)
    for metric in entry.metrics:
        label = metric.get("label", metric["key"])
        ours, paper, ratio, paper_ratio = [], [], [], []
        for name in runs:
            r = by[name, metric["key"]]
            mark = "" if r["within"] is None else (" ✓" if r["within"] else " ✗")
            given = _fmt(r["paper"])
            if r["paper_range"] is not None:
                band = f"in [{_fmt(r['paper_range'][0])}, {_fmt(r['paper_range'][1])}]"
                given = band if r["paper"] is None else f"{given} ({band})"
            value = _fmt(r["ours"])
            if r["ours_min"] is not None:
                value = f"{value} [{_fmt(r['ours_min'])}, {_fmt(r['ours_max'])}]"
            ours.append(value + mark)
            paper.append(given)
            if "ratio_to" in metric:
                text = _fmt(r["ratio"])
                if r.get("ratio_ci_low") is not None:
                    text = f"{text} ({_fmt(r['ratio_ci_low'])}-{_fmt(r['ratio_ci_high'])})"
                ratio.append(text)
                paper_ratio.append(_fmt(r["paper_ratio"]))
        columns = [(label, ours)]
        if any(c != "-" for c in paper):
            columns.append(("paper", paper))
        if "ratio_to" in metric:
            columns.append((f"ratio to {metric['ratio_to']}", ratio))
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
        lines += [_row(header), "|" + " --- |" * len(header)]
        lines += [_row([name, *(cells[i] for _, cells in table)])
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


def draw_speed_classes(spec: dict[str, Any], frames: dict[str, Any], path: Path) -> str:
    """Grouped bars of :func:`speed_class_errors` per run with each class's limit; writes
    ``<file>.csv`` beside the figure and returns the markdown table."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np
    import pandas as pd

    names = list(spec.get("runs", list(frames)))
    per_run = {n: speed_class_errors(frames[n], spec) for n in names}
    classes = [r["class"] for r in per_run[names[0]]]
    limits = [next((per_run[n][k]["limit"] for n in names if per_run[n][k]["limit"]
                    is not None), None) for k in range(len(classes))]
    pd.DataFrame([{"run": n, **r} for n in names for r in per_run[n]]).to_csv(
        path.with_suffix(".csv"), index=False)
    fig, ax = plt.subplots(figsize=(10.5, 4.5), layout="constrained")
    x = np.arange(len(classes))
    width = 0.8 / (len(names) + 1)
    for i, n in enumerate(names):
        heights = [r["max_abs_error"] or 0.0 for r in per_run[n]]
        bars = ax.bar(x + (i - len(names) / 2) * width, heights, width, label=n)
        for bar, r in zip(bars, per_run[n], strict=True):
            if r["met"] is False:
                ax.annotate("x", (bar.get_x() + bar.get_width() / 2, bar.get_height()),
                            ha="center", va="bottom", color="red", fontsize=8)
    lim = [v if v is not None else np.nan for v in limits]
    ax.bar(x + (len(names) / 2) * width, lim, width, color="none", edgecolor="black",
           hatch="//", label="limit (strictest in class)")
    ax.set_yscale("log")
    ax.set_xticks(x, classes)
    ax.set_xlabel("reference speed class (km/h)")
    ax.set_ylabel(spec.get("ylabel", "max |speed error|"))
    ax.grid(True, axis="y", alpha=0.3)
    legend_outside(ax)
    fig.suptitle(spec.get("title", ""))
    fig.savefig(path, dpi=PLOT_DPI, format=Path(path).suffix.lstrip(".") or "png",
                bbox_inches="tight")
    plt.close(fig)
    lines = [_row(["class", "limit", *names]), "|" + " --- |" * (len(names) + 2)]
    for k, cls in enumerate(classes):
        cells = []
        for n in names:
            r = per_run[n][k]
            cells.append("-" if r["max_abs_error"] is None else
                         f"{_fmt(r['max_abs_error'])} {'✓' if r['met'] else '✗'}")
        lines.append(_row([cls, _fmt(limits[k]) if limits[k] is not None else "-", *cells]))
    lines += ["", "max |error| per class of the reference speed over the units (✓ / ✗: every "
              "sample within its own allowance); limit: the class's strictest allowance."]
    if spec.get("paper"):
        lines += ["", f"Paper: {spec['paper']}"]
    return "\n".join(lines)


MEMBER_ROWS = 2000  # rows of a member's series at most: the ensemble bands, evenly thinned


def record_series(record: Record, name: str, folder: Path, specs: list[dict[str, Any]],
                  scenario: Any, scalars: bool = True, max_rows: int | None = None) -> None:
    """Keep of ``folder/results.csv`` as series ``name`` what ``specs`` draw: the columns they
    read, a ``y_reduce`` pattern (``plant.v[*]``) as one column of that name holding the
    reduction (not every vehicle's column), with ``scalars`` every column of one value per
    train too (no ``[i]`` index), and with ``max_rows`` evenly thinned rows (the last kept)."""
    import numpy as np
    import pandas as pd

    from cosim.run.metrics import matching_columns

    path = folder / "results.csv"
    columns = list(pd.read_csv(path, nrows=0).columns)
    header = pd.DataFrame(columns=columns)
    keep = {c for c in columns if "[" not in c} if scalars else set()
    patterns: dict[str, list[str]] = {}
    for spec in specs:
        if "y_reduce" in spec:
            keep |= figure_columns({**spec, "y": []}, scenario, columns)
            ys = spec["y"] if isinstance(spec["y"], list) else [spec["y"]]
            for y in ys:
                patterns[y] = matching_columns(header, y)
        else:
            keep |= figure_columns(spec, scenario, columns)
    wanted = keep.union(*patterns.values())
    frame = read_csv(path, usecols=[c for c in columns if c in wanted])
    reduced = pd.DataFrame({pattern: frame[cols].to_numpy(dtype=float).mean(axis=1)
                            for pattern, cols in patterns.items()},  # y_reduce = "mean"
                           index=frame.index)
    frame = pd.concat([frame[[c for c in frame.columns if c in keep]], reduced], axis=1)
    if max_rows is not None and len(frame) > max_rows:
        step = -(-len(frame) // max_rows)
        rows = np.unique(np.r_[np.arange(0, len(frame), step), len(frame) - 1])
        frame = frame.iloc[rows].reset_index(drop=True)
    record.series[name] = frame


def record_run_series(entry: Entry, out: Path, record: Record) -> None:
    """The series of the table runs the figures draw, from their results.csv under ``out``,
    added to ``record``."""
    scenarios = run_scenarios(entry)
    for name, specs in _figure_runs(entry, FIGURE_KINDS).items():
        record_series(record, series_name("run", name), out / "runs" / slug(name), specs,
                      scenarios[name])


def _figure_runs(entry: Entry, kinds: tuple[str, ...]) -> dict[str, list[dict[str, Any]]]:
    """Run name -> the ``[[figures]]`` of ``kinds`` that draw it."""
    out: dict[str, list[dict[str, Any]]] = {}
    for spec in entry.figures:
        if spec.get("kind", "overlay") in kinds:
            for run in spec.get("runs", [r["name"] for r in entry.runs]):
                out.setdefault(run, []).append(spec)
    return out


def simulate(entry: Entry, out: Path, workers: int | None = None, seeds: int | None = None,
             rounding: bool = True, scheduler: str | None = None, plot_format: str = "png",
             previous: Record | None = None) -> Record:
    """Every simulation ``entry`` needs (its runs, sweeps and claims' members), through
    :mod:`cosim.run.runner`; the record of their results and of the series the figures draw.
    A job ``previous`` holds with the same specification is taken from it, not run again,
    where ``previous`` ran with this tree's simulation inputs, K and rounding path (the run
    folders under ``out`` then hold its files)."""
    from cosim.run.ensemble import simulate_claims
    from cosim.run.sweep import parse_grid, run_sweep

    k = claims_k(entry, seeds)
    digest = simulation_digest(entry.name) if entry.path.parent == REPRODUCE_DIR else ""
    record = Record(entry.name, digest, k, rounding)
    if previous is not None and (previous.simulation, previous.seeds, previous.rounding) != (
            digest, k, rounding):
        why = [what for what, a, b in (("simulation inputs", previous.simulation, digest),
                                       ("K", previous.seeds, k),
                                       ("rounding path", previous.rounding, rounding)) if a != b]
        print(f"{entry.name}: the record under {out} has other {', '.join(why)}: nothing of it "
              "is reused", file=sys.stderr, flush=True)
        previous = None
    run_entry(entry, out, workers, scheduler, plot_format, record, previous)
    save(record, out)  # a checkpoint: an interrupted run resumes from here (--resume)
    record_run_series(entry, out, record)
    for job in sweep_jobs(entry):
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


def wanted_jobs(entry: Entry, k: int, rounding: bool) -> list[Job]:
    """Every simulation the entry's tables, sweeps and claims at ``k`` members read."""
    from cosim.run.ensemble import member_jobs

    return run_jobs(entry) + sweep_jobs(entry) + (member_jobs(entry, k, rounding)
                                                  if entry.claims else [])


def evaluate(entry: Entry, record: Record, out: Path, plot_format: str = "png"
             ) -> tuple[Path, list[dict[str, Any]], list[dict[str, Any]]]:
    """Tables, sweeps' tables and figures, figures, claims and the page of ``entry`` from
    ``record`` alone (no simulation; :class:`cosim.run.record.RecordError` if the record
    lacks a job the entry reads): writes ``table.md`` / ``table.csv`` (``entry.table``),
    ``claims.*`` and the figures in ``plot_format`` to ``out``; returns the table's file,
    its rows and the claims' rows."""
    import pandas as pd

    from cosim.run.ensemble import verdict_summary, write_claims
    from cosim.run.scenario import load_scenario
    from cosim.run.sweep import key_labels, plot_sweep

    check_jobs(record, wanted_jobs(entry, record.seeds, record.rounding))
    out.mkdir(parents=True, exist_ok=True)
    summaries = merged_summaries(entry, {job.key: record.results[ident]
                                         for ident, job in record.jobs.items()
                                         if job.kind == "run"})
    rows = table_rows(entry, summaries)
    derived = derived_rows(entry, summaries)
    ranked = ranking_rows(entry, summaries)
    pd.DataFrame(rows + derived + ranked).to_csv(out / f"{entry.table}.csv", index=False)
    source = (f"{entry.citation} " if entry.citation else "") + (
        f"Reproduced by `cosim reproduce {entry.name}` (entry "
        f"`scenarios/reproduce/{entry.path.name}`).")
    parts = [f"## {entry.title}", "", source, "", table_markdown(entry, rows)]
    if derived:
        parts += ["", derived_markdown(derived)]
    if ranked:
        parts += ["", ranking_markdown(ranked)]
    for sweep in entry.sweeps:
        stored = record.result("sweep", sweep["name"])
        frame = pd.DataFrame(stored["rows"], columns=stored["columns"])
        keys = list(sweep["grid"])
        target = out / slug(sweep["name"])
        target.mkdir(parents=True, exist_ok=True)
        frame.to_csv(target / "sweep.csv", index=False)
        ok = frame[frame["status"] == "ok"]
        if len(ok):
            first = load_scenario(sweep["scenarios"][0])
            named = {Path(p).stem: load_scenario(p).description for p in sweep["scenarios"]}
            named = {n: v for n, v in named.items() if v} | sweep.get("labels", {})
            plot_sweep(ok, keys, target / f"sweep.{plot_format}", key_labels(first, keys),
                       named)
        keep = [c for c in ("scenario", *keys, "stop_error_m", "controller_executions",
                            "command_switches", "qp_infeasible") if c in frame]
        parts += ["", f"### Sweep {sweep['name']}", "", _frame_markdown(frame[keep]), "",
                  f"![{sweep['name']}]({target.name}/sweep.{plot_format})"]
    scenarios = run_scenarios(entry)
    frames = {name: record.frame(series_name("run", name))
              for name in _figure_runs(entry, FIGURE_KINDS)}
    for spec in entry.figures:
        file = figure_file(spec, plot_format)
        if spec.get("kind") == "speed_classes":
            table_md = draw_speed_classes(spec, frames, out / file)
            parts += ["", f"![{spec.get('title', file)}]({file})", "", table_md]
            continue
        draw_figure(spec, frames, out / file, scenarios)
        parts += ["", f"![{spec.get('title', file)}]({file})"]
    claim_rows: list[dict[str, Any]] = []
    if entry.claims:  # the verdicts lead the page; the single runs follow
        claim_rows, claims_text = write_claims(entry, record, out, plot_format)
        head = parts[:4]
        stated = (["", "### Every statement of the paper", "",
                   statements_markdown(entry.statements, claim_rows)]
                  if entry.statements else [])
        parts = [*head, verdict_summary(claim_rows, record.seeds), "", "### Claims", "",
                 claims_text.rstrip("\n"), *stated, "", "### Single runs", "",
                 "Each run once, as its scenario is shipped" + "".join(
                     f", at report seed {v} (`{k}`: member 1 of the claims' disturbance "
                     "ensemble)" for k, v in table_seed(entry).items())
                 + " (the claims above are over the seed ensemble).", "", *parts[4:]]
    if entry.notes:
        parts += ["", "### Where we differ from the paper, and why", "", entry.notes.strip()]
    table = out / f"{entry.table}.md"
    table.write_text("\n".join(parts) + "\n")
    return table, rows, claim_rows


def statements_markdown(statements: list[dict[str, Any]], rows: list[dict[str, Any]]) -> str:
    """Each of the paper's statements with the verdicts (adjusted) of the claims that test it,
    or why it is not tested."""
    by_id = {r["id"]: r for r in rows}

    def where(st: dict[str, Any]) -> str:  # its place in the paper: given, or its claims'
        return st.get("where") or "; ".join(dict.fromkeys(
            by_id[c]["source"] for c in st.get("claims") or [] if by_id[c]["source"]))

    lines = [_row(["the paper says", "where", "tested by (verdict, k of K)"]),
             "| --- | --- | --- |"]
    for st in statements:
        if st.get("claims") is not None:
            cell = "; ".join(f"`{c}`: {by_id[c].get('adjusted', by_id[c]['verdict'])} "
                             f"({by_id[c]['k']}/{by_id[c]['K']})" for c in st["claims"])
        else:
            cell = f"not tested: {st['untestable']}"
        lines.append(_row([st["text"], where(st), cell]))
    n = sum(st.get("claims") is not None for st in statements)
    lines += ["", f"{n} of {len(statements)} statements tested by a claim."]
    return "\n".join(lines)


def reproduce(name: str, out_dir: str | Path | None = None, workers: int | None = None,
              seeds: int | None = None, rounding: bool = True, scheduler: str | None = None,
              plot_format: str = "png", echo: bool = True, resume: bool = False) -> Path:
    """Run one entry (:func:`simulate`), keep its record (``record/``,
    :mod:`cosim.run.record`) and write everything made of it (:func:`evaluate`): the tables,
    sweeps, figures (in ``plot_format``: png at 200 dpi, svg or pdf) and, with claims,
    claims.csv/claims.md over ``seeds`` members (default 20; :mod:`cosim.run.ensemble`,
    ``rounding``: also the perturbed floating-point rerun); every batch of runs goes through
    :mod:`cosim.run.runner` (``workers``, ``scheduler``). With ``echo`` the tables are printed
    in 80 columns (:func:`console_text`). With ``resume`` the jobs the folder's record already
    holds (same specification, simulation inputs, K and path) are not run again. Returns the
    table's markdown file."""
    entry = load_entry(name)
    out = Path(out_dir) if out_dir is not None else Path("runs") / "reproduce" / entry.name
    out.mkdir(parents=True, exist_ok=True)
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
    record = simulate(entry, out, workers, seeds, rounding, scheduler, plot_format, previous)
    save(record, out)
    return redraw_entry(name, out, plot_format, echo)


def redraw_entry(name: str, out_dir: str | Path | None = None, plot_format: str = "png",
           echo: bool = True) -> Path:
    """Tables, figures, claims and page of entry ``name`` from the record in ``out_dir``
    (default ``runs/reproduce/NAME``) without simulating (:func:`evaluate`); the folder's
    ``inputs.sha256`` then names the inputs of both (:func:`cosim.run.provenance.
    entry_digest`) when the record's simulation inputs are the tree's. Returns the table's
    markdown file."""
    entry = load_entry(name)
    out = Path(out_dir) if out_dir is not None else Path("runs") / "reproduce" / entry.name
    record = load(out)
    if record.entry != entry.name:
        raise ReproduceError(f"{out}: the record is of {record.entry!r}, not {entry.name!r}")
    inputs = out / INPUTS_FILE
    inputs.unlink(missing_ok=True)
    try:
        table, rows, claim_rows = evaluate(entry, record, out, plot_format)
    except RecordError as err:
        raise ReproduceError(str(err)) from err
    if entry.path.parent == REPRODUCE_DIR and record.simulation == simulation_digest(name):
        inputs.write_text(entry_digest(name) + "\n")
    if echo:
        print(console_text(entry, rows, claim_rows, out), flush=True)
    return table


def run_scenarios(entry: Entry) -> dict[str, Any]:
    """Run name -> its loaded scenario (with the run's ``set``)."""
    from cosim.run.scenario import load_scenario

    return {r["name"]: load_scenario(r["scenario"], r.get("set", {})) for r in entry.runs}


def figure_file(spec: dict[str, Any], plot_format: str = "png") -> str:
    """The file a ``[[figures]]`` entry is drawn to: its ``file`` in ``plot_format``."""
    return f"{Path(spec['file']).stem}.{plot_format}"


def console_text(entry: Entry, rows: list[dict[str, Any]], claim_rows: list[dict[str, Any]],
                 out: Path) -> str:
    """The entry's results for an 80-column terminal: ours per run and metric (columns
    numbered, their names below), the claims (id, k of K, verdict) and where the full tables
    are."""
    import textwrap

    from cosim.run.console import fit_table
    from cosim.run.ensemble import compact_table

    names = {m["key"]: f"m{i + 1}" for i, m in enumerate(entry.metrics)}
    by_run: dict[str, dict[str, Any]] = {}
    for r in rows:
        by_run.setdefault(r["run"], {"run": r["run"]})[names[r["metric"]]] = r["ours"]
    lines = textwrap.wrap(entry.title, 80)
    if by_run:
        lines += ["", fit_table(list(by_run.values()), ["run", *names.values()],
                                title="ours (beside the paper's, with verdicts, in "
                                      f"{entry.table}.md)")]
        lines += textwrap.wrap("; ".join(f"{names[m['key']]} {m.get('label', m['key'])}"
                                         for m in entry.metrics), 80)
    if claim_rows:
        lines += ["", compact_table(claim_rows)]
    full = [f"{entry.table}.md", f"{entry.table}.csv"]
    if claim_rows:
        full += ["claims.md", "claims.csv"]
    lines += ["", f"full tables in {out}/:", "  " + ", ".join(full)]  # a path is never cut
    return "\n".join(lines)


def _frame_markdown(frame: Any) -> str:
    cols = list(frame.columns)
    lines = [_row(cols), "|" + " --- |" * len(cols)]
    for _, row in frame.iterrows():
        lines.append(_row([_fmt(row[c]) for c in cols]))
    return "\n".join(lines)


def claims_summary(out: Path, names: list[str]) -> str:
    """Claims per verdict (after the multiplicity adjustment) per entry, from each entry's
    ``out/<name>/claims.csv`` (an entry without one: no claims)."""
    import pandas as pd

    from cosim.run.ensemble import VERDICTS

    lines = [_row(["entry", "claims", *VERDICTS]), "|" + " --- |" * (2 + len(VERDICTS))]
    for name in names:
        csv = out / name / "claims.csv"
        if not csv.is_file():
            lines.append(_row([name, "0", *("-" for _ in VERDICTS)]))
            continue
        frame = pd.read_csv(csv)
        got = list(frame["adjusted" if "adjusted" in frame else "verdict"])
        lines.append(_row([name, str(len(got)), *(str(got.count(v)) for v in VERDICTS)]))
    return "\n".join(lines)


def reproduce_all(out_dir: str | Path | None = None, workers: int | None = None,
                  seeds: int | None = None, rounding: bool = True,
                  scheduler: str | None = None, plot_format: str = "png") -> Path:
    """Every entry; one ``REPRODUCTION.md`` with the claims held / failed / inconclusive per
    paper and each entry's tables and figures."""
    out = Path(out_dir) if out_dir is not None else Path("runs") / "reproduce"
    out.mkdir(parents=True, exist_ok=True)
    tables = {name: reproduce(name, out / name, workers, seeds, rounding, scheduler,
                              plot_format)
              for name in entry_names()}
    parts = ["# Reproduced results", "", "Made by `cosim reproduce all`; each section by "
             "`cosim reproduce NAME` from the entry in `scenarios/reproduce/`.", "",
             claims_summary(out, list(tables))]
    for name, table in tables.items():
        text = table.read_text()
        # relative links from out/: prefix the entry folder
        text = re.sub(r"\]\((?!http)([^)]+)\)", rf"]({name}/\1)", text)
        parts += ["", text]
    path = out / "REPRODUCTION.md"
    path.write_text("\n".join(parts) + "\n")
    return path
