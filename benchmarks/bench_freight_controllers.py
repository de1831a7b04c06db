"""Per-event cost of each seed 002 freight controller and closed-loop real-time factor of each
freight scenario (prints figures, asserts nothing).

* per event: the controller core's ``compute`` on freight_20km at states along the reference
  (head at the reference speed, 2,000 positions), median over ``--repeat`` passes, microseconds;
* closed loop: each ``seed002_freight_*`` scenario through the event-driven master (FMUs),
  22.8 min route at the 0.01 s plant step; target >= 100x real time.

    python benchmarks/bench_freight_controllers.py [--repeat 3] [--no-scenarios]
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from controllers.fuzzy.fuzzy_pid import FreightFuzzyPid, FuzzyPidParams  # noqa: E402
from controllers.pid.freight_pid import FreightPid, FreightPidParams  # noqa: E402
from controllers.preview.preview import FreightPreview, PreviewParams  # noqa: E402
from controllers.smc.sliding_mode import FreightSlidingMode, SlidingModeParams  # noqa: E402
from cosim.run.scenario import find_scenario  # noqa: E402
from cosim.run.simulate import run_scenario  # noqa: E402
from plants.route import load_route  # noqa: E402

CONTROLLERS = {
    "pid": (FreightPid, FreightPidParams),
    "preview": (FreightPreview, PreviewParams),
    "smc": (FreightSlidingMode, SlidingModeParams),
    "fpid": (FreightFuzzyPid, FuzzyPidParams),
}


def per_event_us(name: str, repeat: int) -> tuple[float, float]:
    """(wall, CPU) microseconds per event, medians over ``repeat`` passes."""
    core_class, params_class = CONTROLLERS[name]
    route = load_route("freight_20km")
    ref = route.reference
    positions = np.linspace(10.0, 19_900.0, 2000)
    walls, cpus = [], []
    for _ in range(repeat):
        core = core_class(params_class(), ref, route)
        t0, c0 = time.perf_counter(), time.process_time()
        for k, s in enumerate(positions):
            core.compute(0.2 * k, {"v": ref.speed(s) * 0.999, "s": float(s)})
        walls.append((time.perf_counter() - t0) / positions.size * 1e6)
        cpus.append((time.process_time() - c0) / positions.size * 1e6)
    return statistics.median(walls), statistics.median(cpus)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--no-scenarios", action="store_true")
    args = parser.parse_args()
    for name in CONTROLLERS:
        wall, cpu = per_event_us(name, args.repeat)
        print(f"{name:8s} per event {wall:8.1f} us wall, {cpu:8.1f} us CPU", flush=True)
    if args.no_scenarios:
        return
    for name in CONTROLLERS:
        load0 = os.getloadavg()[0]
        c0 = time.process_time()
        result = run_scenario(find_scenario(f"seed002_freight_{name}"), plot=False)
        cpu = time.process_time() - c0  # this process: master + both FMUs (in-process)
        s = result.summary
        fmu = s.get("fmu_wall_time_s", {})
        print(f"seed002_freight_{name}: {s['sim_time_s']:.0f} s in {s['wall_time_s']:.1f} s "
              f"wall, {cpu:.1f} s CPU (build and load included), real-time factor "
              f"{s['real_time_factor']} wall / {s['sim_time_s'] / cpu:.0f} CPU (plant "
              f"{fmu.get('plant')} s, controller {fmu.get('controller')} s wall), load average "
              f"{load0:.1f} -> {os.getloadavg()[0]:.1f}", flush=True)


if __name__ == "__main__":
    main()
