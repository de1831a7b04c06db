"""Run every shipped scenario once (event-driven master) and print its headline figures.

    python benchmarks/scenarios_table.py [--algorithm event|fixed|jacobi] [SCENARIO ...]

Prints one row per scenario (stop error, speed-tracking errors, switches, executions, wall time
and real-time factor): the figures quoted in the README and the issue notes come from here.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from cosim.run.scenario import scenario_files  # noqa: E402
from cosim.run.simulate import run_scenario  # noqa: E402

COLUMNS = [("stop_error_m", "stop err m", "{:+.3f}"), ("max_abs_speed_error_kmh", "max|e| km/h",
           "{:.3f}"), ("speed_mse_kmh2", "MSE km2/h2", "{:.4f}"), ("ctcs3_speed_error_ok",
           "CTCS-3", "{}"), ("command_switches", "switches", "{}"), ("max_coupler_force_kn",
           "coupler kN", "{:.1f}"), ("wall_time_s", "wall s", "{:.2f}"), ("real_time_factor",
           "RTF", "{:.0f}")]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenarios", nargs="*")
    parser.add_argument("--algorithm", default=None)
    args = parser.parse_args()
    names = args.scenarios or list(scenario_files())
    header = f"{'scenario':<22}" + "".join(f"{label:>13}" for _, label, _ in COLUMNS)
    print(header + f"{'controller executions':>24}")
    for name in names:
        s = run_scenario(name, algorithm=args.algorithm).summary
        cells = "".join(f"{(fmt.format(s[k]) if s.get(k) is not None else '-'):>13}"
                        for k, _, fmt in COLUMNS)
        execs = {k: v for k, v in s["executions"].items() if k != "plant"}
        print(f"{name:<22}{cells}{str(execs):>24}", flush=True)


if __name__ == "__main__":
    main()
