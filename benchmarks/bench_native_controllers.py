"""Controller wall time and whole-run real-time factor of the shipped closed loops with the
native C controller FMUs against the same loops with the Python controller FMUs, in one run
(prints figures, asserts nothing).

Loops: every shipped scenario whose controller has a native build (``StopPid``,
``EmuSpeedPid3``, ``Empc3``, the seed-004 hybrid MPCs ``Gmpc3`` and ``MbMpc3``, the seed-001
data-driven ``EmuMfac3``, ``EmuIsmc3``, ``EmuGpc3``), through the event-driven master, the
plant the Python FMU in both; where the plant has a native build too, also with both FMUs
native. Each loop runs the first ``--stop-time`` simulated seconds (default 300 s, the whole
run when shorter), median of ``--repeat`` runs after one warm-up run; ``--scenarios`` picks
loops by a glob of the scenario name.

    python benchmarks/bench_native_controllers.py [--repeat 3] [--stop-time 300]
        [--scenarios 'seed001_*']
"""

from __future__ import annotations

import argparse
import fnmatch
import statistics
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from cosim.build.native import NATIVE  # noqa: E402
from cosim.run.scenario import load_scenario, scenario_files  # noqa: E402
from cosim.run.simulate import run_scenario  # noqa: E402


def loops() -> list[tuple[str, tuple[str, ...]]]:
    """(scenario, instances run native) for every shipped loop with a native controller."""
    out = []
    for path in list(scenario_files().values()):
        sc = load_scenario(path)
        comps = sc.components
        if "controller" in comps and comps["controller"].fmu in NATIVE:
            out.append((path.stem, ("controller",)))
            if "plant" in comps and comps["plant"].fmu in NATIVE:
                out.append((path.stem, ("controller", "plant")))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--stop-time", type=float, default=300.0)
    ap.add_argument("--scenarios", default="*", help="glob of the scenario names")
    args = ap.parse_args()
    print("closed loop, event master: controller FMU wall time and whole-run real-time "
          f"factor, Python -> native (median of {args.repeat})")
    for name, natives in loops():
        if not fnmatch.fnmatch(name, args.scenarios):
            continue
        stop = min(load_scenario(name).simulation.stop_time, args.stop_time)
        base = [f"simulation.stop_time={stop}"]
        res = {}
        for label, sets in (("Python", []), ("native", [f"{c}.build=native" for c in natives])):
            run_scenario(name, base + sets, plot=False)  # warm-up (builds, extraction)
            runs = [run_scenario(name, base + sets, plot=False) for _ in range(args.repeat)]
            res[label] = (statistics.median(r.fmu_wall_time_s["controller"] for r in runs),
                          statistics.median(r.wall_time_s for r in runs))
        (pc, pw), (nc, nw) = res["Python"], res["native"]
        print(f"  {name:24s} native {'+'.join(natives):16s} {stop:6g} s: controller "
              f"{pc * 1e3:8.1f} -> {nc * 1e3:7.2f} ms ({pc / nc:5.1f}x)   RTF {stop / pw:7.0f} "
              f"-> {stop / nw:7.0f} ({pw / nw:4.1f}x)")


if __name__ == "__main__":
    main()
