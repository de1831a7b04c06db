"""Campaign benchmark: seed 001's claims over an ensemble (throughput of the shared runner).

Runs the claims' runs of ``papers/seed001/entry.toml`` at K report seeds (main path and,
unless ``--no-rounding``, the perturbed floating-point path;
:func:`cosim.reproduce.verdicts.run_claims` through :mod:`cosim.run.runner`) three ways in one run:
1 worker, 2 local worker processes, and
a 2-worker local Dask cluster; prints the wall times, the load averages before and after, and
the ratios 1 worker / 2 workers and 1 worker / Dask (target >= 1.8x), with the CPU seconds of
each way (on a loaded machine the wall ratio measures the share of the cores left, the CPU
seconds the work the runner adds). Asserts nothing.
``benchmarks/run_all.py`` records the same figures in ``benchmarks/results.json``.

    python benchmarks/bench_campaign.py [--seeds K] [--no-rounding]     (default K = 20)
"""

from __future__ import annotations

import argparse
import contextlib
import io
import os
import resource
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from cosim.reproduce.entry import load_entry  # noqa: E402
from cosim.reproduce.members import claim_jobs  # noqa: E402
from cosim.reproduce.verdicts import run_claims  # noqa: E402

WAYS = (("1 worker", 1, None), ("2 workers", 2, None), ("dask 2 workers", 2, "local-dask"))


def _cpu_s() -> float:
    """CPU seconds of this process and of its finished descendants (pool and Dask workers,
    counted when they exit): the work done, whatever share of the cores the load left."""
    own = resource.getrusage(resource.RUSAGE_SELF)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


def campaign(k: int, rounding: bool = True) -> dict[str, float]:
    """Wall seconds of the seed 001 claims at K = ``k``: 1 worker, 2 workers, Dask x 2; with
    the CPU seconds of each way (``<way> cpu``), the runs per way, the load averages before
    and after and the two ratios."""
    entry = load_entry("seed001")
    out: dict[str, float] = {"seeds": k, "rounding": rounding,
                             "runs": len(claim_jobs(entry, k, rounding)),
                             "load_before": os.getloadavg()[0]}
    with tempfile.TemporaryDirectory() as tmp:
        for label, workers, scheduler in WAYS:
            start, cpu = time.perf_counter(), _cpu_s()
            with contextlib.redirect_stdout(io.StringIO()):
                run_claims(entry, Path(tmp) / label.replace(" ", "_"), k, workers,
                           rounding=rounding, scheduler=scheduler)
            out[label] = time.perf_counter() - start
            out[f"{label} cpu"] = _cpu_s() - cpu
    out["load_after"] = os.getloadavg()[0]
    out["speedup_2_workers"] = out["1 worker"] / out["2 workers"]
    out["speedup_dask"] = out["1 worker"] / out["dask 2 workers"]
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=20, help="K report seeds (default 20)")
    parser.add_argument("--no-rounding", action="store_true",
                        help="the main path only (no perturbed floating-point rerun)")
    args = parser.parse_args()
    r = campaign(args.seeds, not args.no_rounding)
    print(f"K = {r['seeds']}, {r['runs']} runs per way, rounding rerun {r['rounding']}; "
          f"load average {r['load_before']:.1f} -> {r['load_after']:.1f} on "
          f"{os.cpu_count()} cores")
    for label, _, _ in WAYS:
        print(f"{label:>16}: {r[label]:8.1f} s wall, {r[label + ' cpu']:8.1f} s CPU")
    print(f"2 workers vs 1: {r['speedup_2_workers']:.2f}x (target >= 1.8x)")
    print(f"Dask 2 workers vs 1: {r['speedup_dask']:.2f}x (target >= 1.8x)")


if __name__ == "__main__":
    main()
