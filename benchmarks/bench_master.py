"""The master against the minimal hand-written fmpy loop on the same FMUs.

Runs the master (``Master.run``, no summary, no files) and ``raw_loop.raw_fmpy_loop``
alternately, ``repeat`` times each after one warm-up of both, and reports the medians:

* ``loop``: the communication points alone (master: the algorithm's loop; raw: its loop);
* ``run``: also loading (modelDescription, checks), instantiating, initialising, terminating
  (extraction excluded on both sides: the master extracts an FMU once per process).

The ratio is master / raw (1.0 = the master costs nothing over one FMI call per FMU, type and
direction). Pairs alternate so a change of machine load hits both sides alike.

    python benchmarks/bench_master.py [SCENARIO ...] [--repeat N]
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path[:0] = [str(ROOT), str(HERE)]

from raw_loop import raw_fmpy_loop  # noqa: E402

from cosim.run.master import Master  # noqa: E402
from cosim.run.scenario import find_scenario, load_scenario  # noqa: E402

SCENARIOS = ("seed000_stop_pid", "seed002_freight_pid", "seed001_emu_pid")


def master_run(scenario: str) -> tuple[float, float, float]:
    """(loop wall, run wall, loop CPU) seconds of the event-driven master on ``scenario``."""
    master = Master(load_scenario(find_scenario(scenario)))
    t0 = time.perf_counter()
    master.run()
    return master.loop_wall_time, time.perf_counter() - t0, master.loop_cpu_time


def master_vs_raw(scenario: str, repeat: int = 3) -> dict[str, float]:
    """Medians over ``repeat`` alternating pairs: master and raw loop/run walls and ratios."""
    master_run(scenario)
    raw_fmpy_loop(scenario)
    pairs = []
    for _ in range(repeat):
        loop, run, cpu = master_run(scenario)
        raw = raw_fmpy_loop(scenario)
        pairs.append((loop, run, raw["wall_s"], raw["total_s"], cpu, raw["cpu_s"]))
    med = [statistics.median(p[i] for p in pairs) for i in range(6)]
    return {"master_loop_s": med[0], "master_run_s": med[1], "raw_loop_s": med[2],
            "raw_run_s": med[3], "master_loop_cpu_s": med[4], "raw_loop_cpu_s": med[5],
            "loop_ratio": statistics.median(p[0] / p[2] for p in pairs),
            "run_ratio": statistics.median(p[1] / p[3] for p in pairs),
            "loop_cpu_ratio": statistics.median(p[4] / p[5] for p in pairs),
            "load_average": os.getloadavg()[0]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenarios", nargs="*", default=list(SCENARIOS))
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    for scenario in args.scenarios:
        r = master_vs_raw(scenario, args.repeat)
        print(f"{scenario:<22} loop {r['master_loop_s']:.3f} s vs raw {r['raw_loop_s']:.3f} s: "
              f"{r['loop_ratio']:.3f}x; whole run {r['master_run_s']:.3f} s vs raw "
              f"{r['raw_run_s']:.3f} s: {r['run_ratio']:.3f}x; loop CPU {r['loop_cpu_ratio']:.3f}x "
              f"(load {r['load_average']:.1f})",
              flush=True)


if __name__ == "__main__":
    main()
