"""What running the FMUs in a child process costs: ``cosim run``'s isolated path against the
same run in the calling process (``--in-process``).

Both sides call :func:`cosim.run.simulate.run_scenario` with the same options (no plot, results
written to a temporary folder). The isolated side starts it in a forked child
(:func:`cosim.run.simulate.start_run`: process start, the breadcrumb around every FMU call,
the pipe back) and waits for it (:func:`cosim.run.simulate.finish_run`). Pairs alternate
after one warm-up of each, so a change of machine load hits both sides alike; the ratio is the
median over pairs of isolated / in-process wall time. The CPU times count the child's
(``RUSAGE_CHILDREN``) on the isolated side.

    python benchmarks/bench_isolation.py [SCENARIO ...] [--repeat N]
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path[:0] = [str(ROOT)]

from cosim.run import simulate  # noqa: E402
from cosim.run.scenario import find_scenario  # noqa: E402
from cosim.run.simulate import run_scenario  # noqa: E402

SCENARIOS = ("seed000_stop_pid", "seed002_freight_pid")


def _cpu() -> float:
    own = resource.getrusage(resource.RUSAGE_SELF)
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


def one_run(scenario: str, isolated: bool) -> tuple[float, float]:
    """(wall, CPU) seconds of one run of ``scenario``, isolated in a child or in-process."""
    path = find_scenario(scenario)
    with tempfile.TemporaryDirectory() as tmp:
        options = {"out_dir": Path(tmp), "plot": False, "force": True}
        cpu0, t0 = _cpu(), time.perf_counter()
        if isolated:
            simulate.finish_run(simulate.start_run(str(path), **options), Path(tmp), True)
        else:
            run_scenario(path, **options)
        return time.perf_counter() - t0, _cpu() - cpu0


def isolated_vs_in_process(scenario: str, repeat: int = 5) -> dict[str, float]:
    """Medians over ``repeat`` alternating pairs of the isolated and the in-process run."""
    one_run(scenario, False)
    one_run(scenario, True)
    pairs = [(one_run(scenario, True), one_run(scenario, False)) for _ in range(repeat)]
    return {"isolated_s": statistics.median(p[0][0] for p in pairs),
            "in_process_s": statistics.median(p[1][0] for p in pairs),
            "ratio": statistics.median(p[0][0] / p[1][0] for p in pairs),
            "cpu_ratio": statistics.median(p[0][1] / p[1][1] for p in pairs),
            "extra_ms": 1e3 * statistics.median(p[0][0] - p[1][0] for p in pairs),
            "load_average": os.getloadavg()[0]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenarios", nargs="*", default=list(SCENARIOS))
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    for scenario in args.scenarios:
        r = isolated_vs_in_process(scenario, args.repeat)
        print(f"{scenario:<22} isolated {r['isolated_s']:.3f} s vs in-process "
              f"{r['in_process_s']:.3f} s: {r['ratio']:.3f}x wall ({r['extra_ms']:+.0f} ms), "
              f"{r['cpu_ratio']:.3f}x CPU (load {r['load_average']:.1f})", flush=True)


if __name__ == "__main__":
    main()
