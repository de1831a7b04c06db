"""Sweep speed-up: ``cosim sweep`` with 2 worker processes against 1.

Runs the issue's command end to end (a fresh ``python -m cosim.cli`` each time, so imports and
worker start-up count) with ``--workers 1`` and ``--workers 2`` alternately, ``repeat`` times,
and reports the median wall times, the speed-up (workers 1 / workers 2) the CPU time of
each (command and workers) and the load average before and after. On a shared machine the
wall speed-up needs free cores: with Linux's autogroup scheduling all processes of one session
share one session's part of the CPUs, so at a load far above the core count a second worker
gains nothing (the CPU times then show the cost of parallelism: equal CPU = no overhead).
Optionally the same grid on ``--scheduler local-dask`` (its cluster start-up included).

The MPC designs (DARE, terminal set) come from the on-disk design cache
(:mod:`cosim.fmu.disk_cache`) once one sweep has filled it: the alternating pairs measure that
warm case (every sweep after the first on a machine). One further pair runs each command with
its own empty cache (``cold``: the designs computed and scipy imported in every process).

    python benchmarks/bench_sweep.py [--repeat N] [--dask] [--grid controller.N=3..15]
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SCENARIOS = ("seed000_stop_rmpc", "seed000_stop_rsmpc")
GRID = "controller.N=3..15"


def sweep_wall(workers: int, grid: str = GRID, scheduler: str | None = None,
               cold: bool = False) -> tuple[float, float]:
    """(wall, CPU) seconds of one ``cosim sweep`` of both seed-000 MPC scenarios over
    ``grid``; CPU: user + system of the command and its worker processes. ``cold``: with an
    empty design cache of its own."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        p for p in (str(ROOT), os.environ.get("PYTHONPATH", "")) if p)}
    with tempfile.TemporaryDirectory() as tmp:
        if cold:
            env["ATO_COSIM_CACHE"] = str(Path(tmp) / "cache")
        cmd = [sys.executable, "-m", "cosim.cli", "sweep", *SCENARIOS, "--set", grid,
               "--workers", str(workers), "--no-plot", "--out", str(Path(tmp) / "out")]
        if scheduler:
            cmd += ["--scheduler", scheduler]
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        done = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True)
        wall = time.perf_counter() - t0
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpu = (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime)
    if done.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed:\n{done.stderr[-2000:]}")
    return wall, cpu


def speedup(repeat: int = 2, grid: str = GRID, dask: bool = False) -> dict[str, float]:
    """Median walls of workers 1 and 2 (alternating) and their ratio, with load averages."""
    load_before = os.getloadavg()[0]
    sweep_wall(1, grid)  # fills the design cache (a first sweep on this machine)
    one, two, local_dask = [], [], []
    for _ in range(repeat):
        one.append(sweep_wall(1, grid))
        two.append(sweep_wall(2, grid))
        if dask:
            local_dask.append(sweep_wall(2, grid, "local-dask"))
    out = {"workers_1_s": statistics.median(w for w, _ in one),
           "workers_2_s": statistics.median(w for w, _ in two),
           "speedup": statistics.median(a[0] / b[0] for a, b in zip(one, two)),
           "workers_1_cpu_s": statistics.median(c for _, c in one),
           "workers_2_cpu_s": statistics.median(c for _, c in two),
           "load_before": load_before}
    cold_one, cold_two = sweep_wall(1, grid, cold=True), sweep_wall(2, grid, cold=True)
    out.update({"cold_workers_1_s": cold_one[0], "cold_workers_2_s": cold_two[0],
                "cold_speedup": cold_one[0] / cold_two[0],
                "load_after": os.getloadavg()[0]})
    if dask:
        out["local_dask_2_s"] = statistics.median(w for w, _ in local_dask)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=2)
    parser.add_argument("--grid", default=GRID)
    parser.add_argument("--dask", action="store_true", help="also --scheduler local-dask")
    args = parser.parse_args()
    r = speedup(args.repeat, args.grid, args.dask)
    print(f"cosim sweep {' '.join(SCENARIOS)} --set {args.grid}: --workers 1 "
          f"{r['workers_1_s']:.1f} s, --workers 2 {r['workers_2_s']:.1f} s, speed-up "
          f"{r['speedup']:.2f}x; CPU {r['workers_1_cpu_s']:.1f} s vs {r['workers_2_cpu_s']:.1f} s"
          + f"; cold design cache {r['cold_workers_1_s']:.1f} s vs {r['cold_workers_2_s']:.1f} s,"
          f" {r['cold_speedup']:.2f}x"
          + (f", local-dask (2 workers) {r['local_dask_2_s']:.1f} s"
                                    if args.dask else "")
          + f" (load {r['load_before']:.1f} -> {r['load_after']:.1f})")


if __name__ == "__main__":
    main()
