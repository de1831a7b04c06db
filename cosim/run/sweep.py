"""Parameter sweeps: one scenario (or several) over a grid of overrides, in parallel processes.

``run_sweep("seed000_stop_rsmpc", {"controller.N": range(3, 16)}, "runs/sweep", workers=2)``
runs every grid point with :func:`cosim.run.master.run_scenario` in a process pool, and writes

* ``sweep.csv``: one row per run (scenario, the grid values, the summary figures);
* ``sweep.png``: stop error against the first grid key, one line per scenario, with the
  +-0.5 m stop window, and the command switches / controller executions (the paper's Fig. 11
  plus the switch counts).

Grid values on the command line (:func:`parse_grid`): ``controller.N=3..15`` (integer range,
inclusive), ``controller.beta=1,2,4`` (list) or a single value.
"""

from __future__ import annotations

import itertools
import multiprocessing
import os
from collections.abc import Iterable, Sequence
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import pandas as pd

STOP_WINDOW_M = 0.5  # seed 000: ATO stop window +-50 cm

SUMMARY_COLUMNS = ("stop_error_m", "command_switches", "qp_solves", "qp_infeasible",
                   "qp_solve_time_median_s", "speed_rmse_mps", "max_jerk_mps3", "wall_time_s")


def parse_grid(items: Iterable[str]) -> dict[str, list[Any]]:
    """``["controller.N=3..15", "controller.beta=1,2"]`` -> ``{"controller.N": [3, .., 15], ..}``.
    """
    from cosim.run.scenario import parse_value

    grid: dict[str, list[Any]] = {}
    for item in items:
        key, sep, text = item.partition("=")
        if not sep or not key.strip() or not text.strip():
            raise ValueError(f"--set {item!r}: expected KEY=VALUES, e.g. controller.N=3..15")
        text = text.strip()
        if ".." in text:
            lo, _, hi = text.partition("..")
            try:
                first, last = int(lo), int(hi)
            except ValueError as err:
                raise ValueError(f"--set {item!r}: a range needs integers, e.g. 3..15") from err
            if last < first:
                raise ValueError(f"--set {item!r}: empty range {first}..{last}")
            grid[key.strip()] = list(range(first, last + 1))
        else:
            grid[key.strip()] = [parse_value(v.strip()) for v in text.split(",")]
    return grid


def grid_points(grid: dict[str, Sequence[Any]]) -> list[dict[str, Any]]:
    """Cartesian product of the grid, in order (first key slowest)."""
    keys = list(grid)
    return [dict(zip(keys, values, strict=True))
            for values in itertools.product(*(list(grid[k]) for k in keys))]


def _run_point(scenario: str, point: dict[str, Any]) -> dict[str, Any]:
    """One grid point in a worker process: the summary figures of the run."""
    from cosim.run.master import run_scenario

    result = run_scenario(scenario, overrides=dict(point), build=False, plot=False)
    summary = result.summary
    row: dict[str, Any] = {"scenario": Path(str(scenario)).stem, **point}
    for key in SUMMARY_COLUMNS:
        row[key] = summary.get(key)
    execs = summary.get("executions", {})
    row["controller_executions"] = execs.get("controller") if isinstance(execs, dict) else None
    return row


def run_sweep(scenario: str | Sequence[str], grid: dict[str, Sequence[Any]],
              out_dir: str | Path | None = None, workers: int | None = None,
              plot: bool = True) -> pd.DataFrame:
    """Run every grid point of every scenario in ``workers`` processes (default: CPU count).

    FMUs are built (if stale) once, before the pool starts. Returns one row per run; with
    ``out_dir`` writes ``sweep.csv`` and, with ``plot``, ``sweep.png``.
    """
    from cosim.run.master import ensure_built
    from cosim.run.scenario import find_scenario, load_scenario

    scenarios = [scenario] if isinstance(scenario, (str, Path)) else list(scenario)
    if not scenarios:
        raise ValueError("run_sweep: no scenario given")
    if not grid:
        raise ValueError("run_sweep: empty grid")
    points = grid_points(grid)
    paths = [str(find_scenario(s)) for s in scenarios]
    for path in paths:  # fail early on a bad override, and build what is missing
        ensure_built(load_scenario(path, points[0]))
    jobs = [(path, point) for path in paths for point in points]
    workers = max(1, min(workers or os.cpu_count() or 1, len(jobs)))
    if workers == 1:
        rows = [_run_point(path, point) for path, point in jobs]
    else:
        ctx = multiprocessing.get_context("spawn")  # fresh interpreters: no inherited FMUs
        with ProcessPoolExecutor(max_workers=workers, mp_context=ctx) as pool:
            futures = [pool.submit(_run_point, path, point) for path, point in jobs]
            rows = [f.result() for f in futures]
    frame = pd.DataFrame(rows)
    if out_dir is not None:
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        frame.to_csv(out / "sweep.csv", index=False)
        if plot:
            plot_sweep(frame, list(grid), out / "sweep.png")
    return frame


def plot_sweep(frame: pd.DataFrame, keys: list[str], path: str | Path) -> None:
    """Fig.-11-style plot: stop error (cm) and command switches / executions vs the first key."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    x = keys[0]
    others = keys[1:]
    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(7.5, 7), sharex=True)
    for label, group in frame.groupby(["scenario", *others], sort=False):
        name = label if isinstance(label, str) else " ".join(
            [str(label[0])] + [f"{k}={v}" for k, v in zip(others, label[1:], strict=True)])
        group = group.sort_values(x)
        ax1.plot(group[x], 100.0 * group["stop_error_m"], marker="o", label=name)
        line, = ax2.plot(group[x], group["command_switches"], marker="s",
                         label=f"{name}: switches")
        if group["controller_executions"].notna().all():
            ax2.plot(group[x], group["controller_executions"], marker="^", linestyle="--",
                     color=line.get_color(), label=f"{name}: executions")
    for sign in (-1, 1):
        ax1.axhline(sign * 100 * STOP_WINDOW_M, color="red", linestyle=":", linewidth=1)
    ax1.set_ylabel("stop error (cm)")
    ax1.set_title("Stop error and command switches vs " + x)
    ax1.grid(True, alpha=0.3)
    ax1.legend(fontsize=8)
    ax2.set_xlabel(x)
    ax2.set_ylabel("count")
    ax2.grid(True, alpha=0.3)
    ax2.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
