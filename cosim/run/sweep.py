"""Parameter sweeps: one scenario (or several) over a grid of overrides, in parallel processes.

``run_sweep("stop_rsmpc", {"controller.N": range(3, 16)}, "runs/sweep", workers=2)``
runs every grid point with :func:`cosim.run.simulate.run_scenario` in a process pool, and writes

* ``sweep.csv``: one row per run (scenario, the grid values, ``status`` ok / failed /
  interrupted, ``error``, the summary figures, and last ``inputs_digest``: a digest of the
  scenario file's content and the point's values), appended as each run finishes, so a
  failed point does not stop the others and an interrupted sweep keeps its finished rows;
  with ``resume`` the points already ``ok`` in an existing ``sweep.csv`` are not run again
  when their digest is today's (an edited scenario, or a row torn by a full disk, which
  lacks its last field, is run again);
* ``sweep.png``: stop error against the first grid key, one line per scenario, with the
  +-0.5 m stop window, and the command switches / controller executions (a stopping study's
  figure over the horizon, plus the switch counts).

Grid values on the command line (:func:`parse_grid`): ``controller.N=3..15`` (integer range,
inclusive), ``controller.beta=1,2,4`` (list) or a single value.
"""

from __future__ import annotations

import csv
import functools
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import pandas as pd

from cosim.run import dask_sweep, interrupt, isolation, runner
from cosim.run.figures.sweep import key_labels, plot_sweep
from cosim.run.grid import MAX_RUNS, check_runs, grid_points, parse_grid
from cosim.run.master import SimulationError, warm_up
from cosim.run.master.loading import archive_names
from cosim.run.scenario import (
    Scenario,
    ScenarioError,
    blame_override,
    check_against_fmus,
    find_scenario,
    load_scenario,
)
from cosim.run.simulate import ensure_built, run_scenario

__all__ = ["MAX_RUNS", "check_runs", "grid_points", "parse_grid", "run_sweep"]


SUMMARY_COLUMNS = ("stop_error_m", "command_switches", "qp_solves", "qp_infeasible",
                   "qp_solve_time_median_s", "speed_rmse_mps", "max_jerk_mps3", "wall_time_s")


def run_point(scenario: Any, point: dict[str, Any]) -> dict[str, Any]:
    """One grid point (in a worker): status, error and the summary figures. ``scenario`` is
    a path (loaded here with ``point`` as overrides) or a loaded :class:`Scenario` (already
    overridden). Never raises for a failing run: the row says what went wrong."""
    loaded = isinstance(scenario, Scenario)
    name = Path(str(scenario.path if loaded else scenario)).stem
    row: dict[str, Any] = {"scenario": name, **point, "status": "ok", "error": ""}
    for key in (*SUMMARY_COLUMNS, "controller_executions"):
        row[key] = None
    try:
        result = run_scenario(scenario, overrides=None if loaded else dict(point), build=False,
                              plot=False)
    except interrupt.Interrupted as err:
        return {**row, "status": "interrupted", "error": str(err)}
    except (ScenarioError, SimulationError, ValueError, OSError) as err:
        return {**row, "status": "failed", "error": str(err)}
    summary = result.summary
    for key in SUMMARY_COLUMNS:
        row[key] = summary.get(key)
    execs = summary.get("executions", {})
    row["controller_executions"] = execs.get("controller") if isinstance(execs, dict) else None
    return row


# summary counts: integers, empty for a failed point
COUNT_COLUMNS = ("command_switches", "qp_solves", "qp_infeasible", "controller_executions")


def check_point(path: str, point: dict[str, Any]) -> None:
    """Raise :class:`cosim.run.scenario.ScenarioError` (naming the ``--set`` option) when a grid
    point names no variable or gives a value of the wrong type (``controller.N=abc`` for an
    Integer). A value outside [min, max] is left to the point's run, which fails alone: a
    sweep may probe a range's edge on purpose."""
    sc = load_scenario(path, point)
    descriptions = {c.name: _description(c.fmu_path)
                    for c in sc.components.values() if c.fmu_path.is_file()}
    if len(descriptions) < len(sc.components):
        return  # a missing FMU: the run of the point says which
    try:
        check_against_fmus(sc, descriptions, ranges=False)
    except ScenarioError as err:
        raise blame_override(err, sc.path, sc.overrides) from None


@functools.lru_cache(maxsize=64)
def _cached_description(path: Path, mtime_ns: int) -> Any:
    from fmpy import read_model_description

    archive_names(str(path), path)  # bounded before the XML is parsed
    return read_model_description(str(path))


def _description(path: Path) -> Any:
    """The FMU's modelDescription, read once per file version."""
    return _cached_description(path, path.stat().st_mtime_ns)


def _key(scenario: str, point: dict[str, Any]) -> tuple[str, ...]:
    """A grid point as text, the same whether it comes from the grid or from sweep.csv."""
    return (Path(str(scenario)).stem, *(f"{k}={_text(v)}" for k, v in point.items()))


def _text(value: Any) -> str:
    if isinstance(value, float) and value.is_integer():
        return str(int(value))
    return str(value)


DIGEST = "inputs_digest"


def inputs_digest(scenario: str, point: dict[str, Any]) -> str:
    """What a sweep row depends on, as 16 hex digits (SHA-256): the scenario file's bytes
    and the point's values as text."""
    import hashlib

    text = "\0".join(_key(scenario, point)).encode()
    return hashlib.sha256(Path(scenario).read_bytes() + b"\0" + text).hexdigest()[:16]


def done_rows(csv_path: Path, keys: list[str], wanted: set[str]) -> list[dict[str, Any]]:
    """The rows of an earlier ``sweep.csv`` or ``perturb.csv`` (for ``resume``) whose
    :data:`DIGEST` is in ``wanted`` (today's inputs; a torn row lacks its last field) and
    whose ``status``, where the file has one, is ``ok``; cells back to what was written."""
    if not csv_path.is_file():
        return []
    earlier = pd.read_csv(csv_path, keep_default_na=False, dtype={DIGEST: str})
    if not set(keys) <= set(earlier.columns):
        raise ValueError(f"{csv_path}: not a sweep over {', '.join(keys)}; cannot resume it")
    if DIGEST not in earlier.columns:  # written without the inputs it depends on
        return []
    text_columns = {"scenario", "status", "error", DIGEST}
    return [{k: v if k in text_columns else _cell(v) for k, v in row.items()}
            for row in earlier.to_dict("records")
            if row.get("status", "ok") == "ok" and row[DIGEST] in wanted]


def _cell(value: Any) -> Any:
    """A sweep.csv cell read as text back to what was written: None for an empty cell, an int
    or a float for a number (a column with empty cells is read as text, not as numbers)."""
    if not isinstance(value, str):
        return value
    if value == "":
        return None
    for kind in (int, float):
        try:
            return kind(value)
        except ValueError:
            pass
    return value


class RowWriter:
    """Appends rows to sweep.csv as they arrive (header first), flushed after each row."""

    def __init__(self, path: Path, columns: list[str], rows: list[dict[str, Any]]) -> None:
        self.path, self.columns = path, columns
        self.file = path.open("w", newline="")
        self.writer = csv.DictWriter(self.file, fieldnames=columns, extrasaction="ignore",
                                     lineterminator="\n")
        self.writer.writeheader()
        for row in rows:
            self.add(row)

    def add(self, row: dict[str, Any]) -> None:
        self.writer.writerow({k: "" if row.get(k) is None else row.get(k) for k in self.columns})
        self.file.flush()

    def close(self) -> None:
        self.file.close()


def run_sweep(scenario: str | Sequence[str], grid: dict[str, Sequence[Any]],
              out_dir: str | Path | None = None, workers: int | None = None,
              plot: bool = True, resume: bool = False, scheduler: str | None = None,
              shared_fmus: bool = False, plot_format: str = "png",
              series_labels: dict[str, str] | None = None,
              time_limit: float | None = None, max_runs: int = MAX_RUNS) -> pd.DataFrame:
    """Run every grid point of every scenario with :func:`cosim.run.runner.run_tasks`: in
    ``workers`` processes (default: CPU count), or on a Dask cluster (``scheduler``: its
    address, or ``"local-dask"`` for a ``LocalCluster`` of ``workers`` processes;
    :mod:`cosim.run.dask_sweep`).

    FMUs are built (if stale) once, before the pool starts. Returns one row per run, in grid
    order, with ``status`` and ``error``; with ``out_dir`` each row is appended to
    ``sweep.csv`` as it finishes (``resume``: the ``ok`` rows of an existing one are kept and
    not run again), then the file is rewritten in grid order and, with ``plot``, ``sweep.png``
    drawn (``sweep.<plot_format>``: png at 200 dpi, svg or pdf; each scenario's series named
    by ``series_labels[scenario name]``, else by the scenario's ``description``).
    SIGINT/SIGTERM: no new point starts, running ones stop (status ``interrupted``), the
    finished rows are written and :class:`cosim.run.interrupt.Interrupted` is raised.
    Each worker runs with one BLAS thread and is reused for many points (the imports and FMU
    extractions happen once per worker). On Dask the FMU files are uploaded to the workers,
    or, with ``shared_fmus``, read by them from the same paths (a shared file system).
    ``time_limit`` (s, wall clock, local workers): a point running longer is stopped and
    failed; a point whose worker crashes fails naming the signal and the FMU call. More than
    ``max_runs`` runs (points times scenarios) are refused before any work (:func:`check_runs`).
    """
    scenarios = [scenario] if isinstance(scenario, (str, Path)) else list(scenario)
    if not scenarios:
        raise ValueError("run_sweep: no scenario given")
    if not grid:
        raise ValueError("run_sweep: empty grid")
    runner.check_workers(workers, scheduler)
    check_runs(grid, len(scenarios), max_runs)
    points = grid_points(grid)
    paths = [str(find_scenario(s)) for s in scenarios]
    for path in paths:  # fail early on a bad scenario or key, and build what is missing
        ensure_built(load_scenario(path, points[0]))
        for point in points:  # every point's values against the FMUs, before any runs
            check_point(path, point)
    jobs = [(path, point) for path in paths for point in points]
    order = {_key(path, point): i for i, (path, point) in enumerate(jobs)}
    out = Path(out_dir) if out_dir is not None else None
    done: list[dict[str, Any]] = []
    digests = {_key(path, point): inputs_digest(path, point) for path, point in jobs}
    if out is not None and resume:  # rows of these inputs only, whole (the digest is last)
        done = done_rows(out / "sweep.csv", list(grid), set(digests.values()))
    skip = {_key(r["scenario"], {k: r[k] for k in grid}) for r in done}
    todo = [(path, point) for path, point in jobs if _key(path, point) not in skip]
    columns = ["scenario", *grid, "status", "error", *SUMMARY_COLUMNS, "controller_executions",
               DIGEST]
    writer = None
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
        writer = RowWriter(out / "sweep.csv", columns, done)
    rows = list(done)

    def finished(row: dict[str, Any]) -> None:
        row = {**row, DIGEST: digests.get(_key(row["scenario"], {k: row[k] for k in grid}))}
        rows.append(row)
        if writer is not None:
            writer.add(row)

    try:
        _execute(todo, workers, finished, scheduler, shared_fmus, plot_format, time_limit)
    finally:
        if writer is not None:
            writer.close()
        rows.sort(key=lambda r: order.get(_key(r["scenario"], {k: r[k] for k in grid}), 0))
        frame = pd.DataFrame(rows, columns=columns)
        if out is not None:
            written = frame.copy()
            for col in COUNT_COLUMNS:  # integers with empty cells (a failed point): not 245.0
                written[col] = pd.to_numeric(written[col]).round().astype("Int64")
            written.to_csv(out / "sweep.csv", index=False)
            if plot and (frame["status"] == "ok").any():
                named = {Path(p).stem: load_scenario(p, points[0]).description for p in paths}
                named = {k: v for k, v in named.items() if v} | (series_labels or {})
                plot_sweep(frame[frame["status"] == "ok"], list(grid),
                           out / f"sweep.{plot_format}",
                           key_labels(load_scenario(paths[0], points[0]), list(grid)), named)
    return frame


def warm_up_for(jobs: list[tuple[str, dict[str, Any]]]) -> Callable[[], None]:
    """Before the pool forks: load every FMU of the sweep once (extracted, its bundled modules
    imported, the instance freed again), so a forked worker starts with nothing left to
    import or extract (a spawned interpreter would import and extract again in each
    worker)."""

    def warm() -> None:
        fmus: dict[str, None] = {}
        for path, point in jobs:
            try:
                for comp in load_scenario(path, dict(point)).components.values():
                    fmus.setdefault(str(comp.fmu_path))
            except (ValueError, OSError):
                continue  # the point fails in its worker, with this error
        for fmu in fmus:
            warm_up(Path(fmu))

    return warm


def _execute(jobs: list[tuple[str, dict[str, Any]]], workers: int | None,
             finished: Callable[[dict[str, Any]], None], scheduler: str | None = None,
             shared_fmus: bool = False, plot_format: str = "png",
             time_limit: float | None = None) -> None:
    """Run ``jobs`` (scenario path, grid point) with the shared runner, handing each row to
    ``finished`` as it arrives; on a signal, the running points stop (status
    ``interrupted``) and Interrupted is raised. Along a swept horizon or resolution the cost
    grows, so the last grid points start first and the short ones fill the end (the workers
    finish together; rows are put back in grid order by the caller)."""

    def failed(task: runner.Task, err: BaseException) -> None:
        path, point = task.key
        known = isinstance(err, (isolation.ChildFailed, runner.TimeLimitExceeded))
        finished({"scenario": Path(path).stem, **point, "status": "failed",
                  "error": str(err) if known else
                  f"worker process failed: {type(err).__name__}: {err}"})

    label = "sweep"
    if scheduler is None:
        tasks = [runner.Task((path, point), run_point, (path, point))
                 for path, point in reversed(jobs)]
        runner.run_tasks(tasks, lambda _t, row: finished(row), failed, workers,
                         label=label, warm_up=warm_up_for(jobs), what="the sweep",
                         time_limit=time_limit)
        return
    tasks, blobs = dask_sweep.tasks(jobs, finished, run_point, shared_fmus)
    runner.run_tasks(tasks, lambda _t, row: finished(row), failed, workers, scheduler,
                     label=label, broadcast=blobs, what="the sweep")
