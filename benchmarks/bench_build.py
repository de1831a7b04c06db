"""Campaign benchmark: an entry's claims on the native C builds against the Python builds.

Runs the claims' members of an entry (default seed 002: the freight plant and its four
controllers, all native) at K report seeds on the main path (:func:`cosim.reproduce.verdicts.
run_claims`, ``--build python`` then ``--build native``, each on 2 workers) in one run, and
prints the wall and CPU seconds of each (the CPU of this process and its finished workers),
the load averages before and after, the ratio python / native of each, and whether the two
give the same verdicts and members on the claimed side. Asserts nothing.

    python benchmarks/bench_build.py [--entry seed002] [--seeds K]     (default K = 5)
"""

from __future__ import annotations

import argparse
import contextlib
import io
import os
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from bench_campaign import _cpu_s  # noqa: E402

from cosim.reproduce.entry import load_entry  # noqa: E402
from cosim.reproduce.members import claim_jobs  # noqa: E402
from cosim.reproduce.verdicts import run_claims  # noqa: E402

BUILDS = ("python", "native")


def compare(name: str, k: int) -> dict[str, object]:
    """Wall and CPU seconds of entry ``name``'s claims at K = ``k`` per build, the ratios
    python / native and whether the verdicts agree."""
    entry = load_entry(name)
    out: dict[str, object] = {"entry": name, "seeds": k,
                              "runs": len(claim_jobs(entry, k, False)),
                              "load_before": os.getloadavg()[0]}
    rows = {}
    with tempfile.TemporaryDirectory() as tmp:
        for build in BUILDS:
            start, cpu = time.perf_counter(), _cpu_s()
            with contextlib.redirect_stdout(io.StringIO()):
                rows[build] = run_claims(entry, Path(tmp) / build, k, 2, rounding=False,
                                         build=build)
            out[f"{build} wall"] = time.perf_counter() - start
            out[f"{build} cpu"] = _cpu_s() - cpu
    out["load_after"] = os.getloadavg()[0]
    for what in ("wall", "cpu"):
        out[f"ratio {what}"] = out[f"python {what}"] / out[f"native {what}"]
    out["same verdicts"] = ([(r.claim.id, r.verdict, r.main.k) for r in rows["python"]]
                            == [(r.claim.id, r.verdict, r.main.k) for r in rows["native"]])
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--entry", default="seed002", help="reproduction entry (seed002)")
    parser.add_argument("--seeds", type=int, default=5, help="K report seeds (default 5)")
    args = parser.parse_args()
    r = compare(args.entry, args.seeds)
    print(f"{r['entry']}, K = {r['seeds']}, {r['runs']} runs per build, main path only; load "
          f"average {r['load_before']:.1f} -> {r['load_after']:.1f} on {os.cpu_count()} cores")
    for build in BUILDS:
        print(f"{build:>8}: {r[f'{build} wall']:8.1f} s wall, {r[f'{build} cpu']:8.1f} s CPU")
    print(f"python / native: {r['ratio wall']:.2f}x wall, {r['ratio cpu']:.2f}x CPU; "
          f"same verdicts: {r['same verdicts']}")


if __name__ == "__main__":
    main()
