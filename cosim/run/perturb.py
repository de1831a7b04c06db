"""Model-mismatch studies: a sweep whose runs draw seeded random plant parameters.

``cosim sweep stop_rmpc --set controller.N=5,10 --perturb plant.mass=+-10%
--perturb plant.brake_time_constant=0.3..0.6 --samples 50 --seed 1`` runs every scenario at
every grid point with the same ``samples`` parameter draws (common random numbers: the
controllers are compared on the same plants). Only the perturbed parameters change; the
controllers keep their nominal parameters. The forms of ``--perturb KEY=SPEC`` and the
draws: :mod:`cosim.run.perturbation`. Writes ``perturb.csv`` (one row per run: scenario, grid
values, sample, drawn values, the summary figures, the command's least and largest value),
``perturb_summary.csv`` (per scenario and grid point: the stop-error distribution, runs inside
the stop window, executions, infeasible counts) and ``perturb.png`` (box plots of stop error
and executions).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import pandas as pd

from cosim.run import runner
from cosim.run.figures.perturb import plot_perturbed
from cosim.run.grid import MAX_RUNS, check_runs, grid_points
from cosim.run.metrics import STOP_WINDOW_M
from cosim.run.perturbation import Perturbation, draw_samples, nominal_values
from cosim.run.scenario import ScenarioError, find_scenario, load_scenario
from cosim.run.simulate import ensure_built, run_scenario
from cosim.run.sweep import (
    DIGEST,
    SUMMARY_COLUMNS,
    RowWriter,
    done_rows,
    inputs_digest,
)

COUNTERS = ("qp_infeasible_after_stop", "events_moving", "events_standstill")


def _run_sample(scenario: str, point: dict[str, Any], index: int,
                draw: dict[str, float]) -> dict[str, Any]:
    """One perturbed run in a worker: the drawn values, summary figures and command range."""
    result = run_scenario(scenario, overrides={**point, **draw}, build=False, plot=False)
    summary = result.summary
    row: dict[str, Any] = {"scenario": Path(str(scenario)).stem, **point, "sample": index,
                           **draw}
    for key in (*SUMMARY_COLUMNS, *COUNTERS):
        value = summary.get(key)
        row[key] = value if not isinstance(value, dict) else None
    execs = summary.get("executions", {})
    row["controller_executions"] = execs.get("controller") if isinstance(execs, dict) else None
    command = result.scenario.summary.get("command")
    if isinstance(command, str) and command in result.frame:
        series = result.frame[command].to_numpy(dtype=float)
        row["command_min"], row["command_max"] = float(series.min()), float(series.max())
    row["completed"] = summary.get("completed")
    return row


def run_perturbed(scenario: str | Sequence[str], grid: dict[str, Sequence[Any]],
                  perts: Sequence[Perturbation], samples: int, seed: int,
                  out_dir: str | Path | None = None, workers: int | None = None,
                  plot: bool = True, plot_format: str = "png", max_runs: int = MAX_RUNS,
                  resume: bool = False) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Every scenario at every grid point on the same ``samples`` draws, in ``workers``
    processes (:func:`cosim.run.runner.run_tasks`). Returns (one row per run, one row per
    scenario and grid point); with ``out_dir`` writes perturb.csv (each run's row appended as
    it finishes, last its :data:`~cosim.run.sweep.DIGEST` of the scenario file, point, sample
    and drawn values, so an interrupted study keeps its finished runs; then rewritten in
    order), perturb_summary.csv and ``perturb.<plot_format>``. With ``resume`` the runs
    whose rows an existing perturb.csv holds with today's digest are not run again. More
    than ``max_runs`` runs are refused before any work."""
    scenarios = [scenario] if isinstance(scenario, (str, Path)) else list(scenario)
    if not scenarios or not perts:
        raise ValueError("run_perturbed: no scenario or no perturbation given")
    check_runs(grid, len(scenarios), max_runs, samples)
    points = grid_points(grid) if grid else [{}]
    paths = [str(find_scenario(s)) for s in scenarios]
    draws: list[dict[str, float]] | None = None
    for path in paths:
        ensure_built(load_scenario(path, {**points[0]}))
        nominals = nominal_values(path, [p.key for p in perts], {**points[0]})
        these = draw_samples(perts, nominals, samples, seed)
        if draws is None:
            draws = these
        elif any(p.kind != "range" for p in perts) and these != draws:
            raise ScenarioError(f"{path}: its nominal plant differs from {paths[0]}'s: the "
                                f"samples would not be the same plants")
    assert draws is not None
    for path in paths:  # fail early on a bad key or value
        load_scenario(path, {**points[0], **draws[0]})
    jobs = [(path, point, i, d) for path in paths for point in points
            for i, d in enumerate(draws)]
    digests = [inputs_digest(path, {**point, "sample": i, **d}) for path, point, i, d in jobs]
    out = Path(out_dir) if out_dir is not None else None
    kept = {row[DIGEST]: row for row in (
        done_rows(out / "perturb.csv", [*grid, "sample"], set(digests))
        if out is not None and resume else [])}
    done = {n: kept[digest] for n, digest in enumerate(digests) if digest in kept}
    columns = ["scenario", *grid, "sample", *(p.key for p in perts), *SUMMARY_COLUMNS,
               *COUNTERS, "controller_executions", "command_min", "command_max", "completed",
               DIGEST]
    writer = None
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
        writer = RowWriter(out / "perturb.csv", columns, list(done.values()))

    def finished(task: runner.Task, row: dict[str, Any]) -> None:
        done[task.key] = row = {**row, DIGEST: digests[task.key]}
        if writer is not None:
            writer.add(row)

    errors: list[tuple[int, BaseException]] = []
    try:
        runner.run_tasks([runner.Task(n, _run_sample, job) for n, job in enumerate(jobs)
                          if n not in done], finished,
                         lambda task, err: errors.append((task.key, err)), workers,
                         label="perturb", what="the mismatch study")
    finally:
        if writer is not None:
            writer.close()
    if errors:  # every sample is needed for the common-random-number comparison
        n, err = errors[0]
        path, point, i, _draw = jobs[n]
        raise ValueError(f"{path} {point} sample {i}: {type(err).__name__}: {err}") from err
    rows = [done[n] for n in range(len(jobs))]
    frame = pd.DataFrame(rows, columns=[  # the command's range where the scenario names one
        c for c in columns if not c.startswith("command_") or any(
            r.get(c) is not None for r in rows)])
    table = summarize(frame, list(grid))
    if out is not None:
        frame.to_csv(out / "perturb.csv", index=False)
        table.to_csv(out / "perturb_summary.csv", index=False)
        if plot:
            plot_perturbed(frame, list(grid), out / f"perturb.{plot_format}")
    return frame, table


def summarize(frame: pd.DataFrame, keys: list[str]) -> pd.DataFrame:
    """Per scenario and grid point: stop error distribution, window hits, executions,
    infeasible counts (sum over the runs and the largest in one run)."""
    rows = []
    for label, group in frame.groupby(["scenario", *keys], sort=False):
        label = label if isinstance(label, tuple) else (label,)
        err = group["stop_error_m"].astype(float)
        row: dict[str, Any] = dict(zip(["scenario", *keys], label, strict=True))
        row.update({
            "runs": len(group),
            "stop_error_min_m": err.min(), "stop_error_median_m": err.median(),
            "stop_error_max_m": err.max(), "max_abs_stop_error_m": err.abs().max(),
            "inside_window": int((err.abs() <= STOP_WINDOW_M).sum()),
            "executions_median": group["controller_executions"].median(),
            "executions_max": group["controller_executions"].max(),
        })
        for col in ("qp_infeasible", "qp_infeasible_after_stop"):
            if col in group and group[col].notna().any():
                row[f"{col}_total"] = int(group[col].fillna(0).sum())
                row[f"{col}_max"] = int(group[col].fillna(0).max())
        if "command_min" in group:
            row["command_min"] = group["command_min"].min()
            row["command_max"] = group["command_max"].max()
        rows.append(row)
    return pd.DataFrame(rows)
