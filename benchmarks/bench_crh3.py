"""Real-time factors of the seed 003 CRH3 runs (prints figures, asserts nothing).

* plant core alone, replaying the forces of a closed-loop eco run (1 s steps);
* plant + GPC cores in a plain loop (no FMI);
* the scenario through the event-driven master (FMUs), summary included;
* the eco profile generation (bisection on V_low), once per process and route.

    python benchmarks/bench_crh3.py [--scenario seed003_crh3_gpc_eco]
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from controllers.common import speed_profiles as sp  # noqa: E402
from controllers.eco.gpc import Crh3Gpc, Crh3GpcParams  # noqa: E402
from cosim.fmu.state import to_ticks  # noqa: E402
from cosim.run.simulate import run_scenario  # noqa: E402
from plants.crh3 import Crh3Params, Crh3Train  # noqa: E402
from plants.route import load_route  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--scenario", default="seed003_crh3_gpc_eco")
    args = ap.parse_args()
    print(f"load average {os.getloadavg()[0]:.1f}")
    route = load_route("seed003_crh3")
    params = Crh3GpcParams()
    sp._CACHE.clear()
    t0 = time.perf_counter()
    prof = sp.generate("eco", route, None, params.track.train(), params.track.settings())
    print(f"eco profile generation: {time.perf_counter() - t0:.2f} s")
    ctl = Crh3Gpc(params, prof)
    plant = Crh3Train(Crh3Params(), route)
    steps = int(prof.arrival_time) + 30
    forces = []
    t0 = time.perf_counter()
    for k in range(steps):
        o = plant.outputs()
        out, _ = ctl.compute(float(k), o)
        forces.append(out["force"])
        plant.advance(to_ticks(k), to_ticks(1.0), {"force": out["force"]})
    loop = time.perf_counter() - t0
    plant = Crh3Train(Crh3Params(), route)
    t0 = time.perf_counter()
    for k, f in enumerate(forces):
        plant.advance(to_ticks(k), to_ticks(1.0), {"force": f})
        plant.outputs()
    alone = time.perf_counter() - t0
    print(f"plant core alone: {steps / alone:.0f}x real time ({alone:.2f} s for {steps} s)")
    print(f"plant + GPC cores: {steps / loop:.0f}x real time ({loop:.2f} s)")
    t0 = time.perf_counter()
    result = run_scenario(args.scenario, out_dir=ROOT / "runs" / "bench_crh3")
    wall = time.perf_counter() - t0
    print(f"{args.scenario} through the master: {result.summary['real_time_factor']}x "
          f"(summary), {wall:.1f} s wall with loading")


if __name__ == "__main__":
    main()
