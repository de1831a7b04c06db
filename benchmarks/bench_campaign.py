"""Campaign benchmark: seed 001's claims over an ensemble (throughput of the claims runner).

Runs the claims' runs of ``scenarios/reproduce/seed001.toml`` at K report seeds (main and
perturbed floating-point path, :func:`cosim.run.ensemble.run_claims`) three ways in one run:
1 worker, 2 local worker processes, and a 2-worker local Dask cluster; prints the wall times
and the ratios 1 worker / 2 workers and 1 worker / Dask (target >= 1.8x). Asserts nothing.

    python benchmarks/bench_campaign.py [--seeds K]     (default K = 20)
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from cosim.run.ensemble import run_claims  # noqa: E402
from cosim.run.reproduce import load_entry  # noqa: E402


def campaign(k: int) -> dict[str, float]:
    """Wall seconds of the seed 001 claims at K = ``k``: 1 worker, 2 workers, Dask x 2."""
    entry = load_entry("seed001")
    walls: dict[str, float] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for label, workers, scheduler in (("1 worker", 1, None), ("2 workers", 2, None),
                                          ("dask 2 workers", 2, "local-dask")):
            start = time.perf_counter()
            run_claims(entry, Path(tmp) / label.replace(" ", "_"), k, workers,
                       scheduler=scheduler)
            walls[label] = time.perf_counter() - start
    return walls


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=20, help="K report seeds (default 20)")
    args = parser.parse_args()
    print(f"load average before: {os.getloadavg()}")
    walls = campaign(args.seeds)
    print(f"load average after: {os.getloadavg()}")
    for label, wall in walls.items():
        print(f"{label:>16}: {wall:8.1f} s")
    one = walls["1 worker"]
    print(f"2 workers vs 1: {one / walls['2 workers']:.2f}x (target >= 1.8x)")
    print(f"Dask 2 workers vs 1: {one / walls['dask 2 workers']:.2f}x (target >= 1.8x)")


if __name__ == "__main__":
    main()
