"""Seed 003 robust MPC: LMI solve time per event, Clarabel against SCS, and the whole-scenario
real-time factor (prints, asserts nothing).

1. Closed loop of the cores (plant :class:`plants.crh3.Crh3Train`, controller
   :class:`controllers.robust.rmpc.Crh3LmiMpc`, eco profile, Clarabel) over ``--seconds`` s:
   the LMI problems of every event are recorded (state and vertices).
2. Replay of those problems (every ``--every``-th) with both solvers on one prebuilt (DPP)
   problem each: wall time per solve (median, p99), failures, and the largest gain difference
   |F_scs - F_clarabel| / |F_clarabel|.
3. The scenario ``seed003_crh3_lmimpc_eco`` through the master: real-time factor and the median
   LMI time the controller reports.

    python benchmarks/bench_seed003.py [--seconds 600] [--every 5] [--no-scenario]
"""

from __future__ import annotations

import argparse
import os
import sys
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from controllers.common.lmi import KothareLmi  # noqa: E402
from controllers.robust.rmpc import Crh3LmiMpc  # noqa: E402
from cosim.fmu.state import to_ticks  # noqa: E402
from cosim.run.scenario import find_scenario  # noqa: E402
from plants.crh3 import Crh3Params, Crh3Train  # noqa: E402
from plants.route import load_route  # noqa: E402

MEASURED = ("v", "s", "traction_limit", "brake_limit")


def record_problems(seconds: int, profile: str = "eco") -> tuple[Crh3LmiMpc, list]:
    """Run the cores; return the controller and every event's (x, vertices) LMI data."""
    starts = {v.name: v.start for v in Crh3LmiMpc.declarations() if v.causality == "parameter"}
    ctl = Crh3LmiMpc.from_parameters({**starts, "profile": profile}, data_dir=ROOT)
    plant = Crh3Train(Crh3Params(), load_route("seed003_crh3"))
    lmi = ctl.law.lmi
    problems: list = []
    original = lmi.solve

    def spy(x, vertices):
        problems.append((np.array(x, float), [(A.copy(), B.copy()) for A, B in vertices]))
        return original(x, vertices)

    lmi.solve = spy  # type: ignore[method-assign]
    for k in range(seconds):
        o = plant.outputs()
        out, _ = ctl.compute(float(k), {n: o[n] for n in MEASURED})
        plant.advance(to_ticks(k), to_ticks(1.0), {"force": out["force"]})
    lmi.solve = original  # type: ignore[method-assign]
    return ctl, problems


def replay(ctl: Crh3LmiMpc, problems: list, every: int) -> dict[str, dict]:
    p, law = ctl.p.rmpc, ctl.law
    chosen = problems[::every]
    out: dict[str, dict] = {}
    gains: dict[str, list] = {}
    for solver in ("clarabel", "scs"):
        lmi = KothareLmi(2, 1, law.lmi.L, np.diag([p.q_speed, p.q_position]),
                         np.array([[p.r_input]]), u_max=[p.u_max], solver=solver)
        times, cpus, fails, F = [], [], 0, []
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            for x, vertices in chosen:
                sol = lmi.solve(x, vertices)
                times.append(sol.solve_time)
                cpus.append(sol.cpu_time)
                fails += not sol.ok
                F.append(sol.F.ravel() if sol.ok else None)
        t = np.array(times) * 1e3
        c = np.array(cpus) * 1e3
        out[solver] = {"median_ms": float(np.median(t)), "p99_ms": float(np.percentile(t, 99)),
                       "cpu_median_ms": float(np.median(c)),
                       "cpu_p99_ms": float(np.percentile(c, 99)),
                       "failures": fails, "solves": len(chosen)}
        gains[solver] = F
    diffs = [np.max(np.abs(b - a)) / np.max(np.abs(a))
             for a, b in zip(gains["clarabel"], gains["scs"], strict=True)
             if a is not None and b is not None]
    out["scs"]["max_rel_gain_diff"] = float(max(diffs)) if diffs else float("nan")
    return out


def scenario(name: str = "seed003_crh3_lmimpc_eco") -> dict:
    from cosim.build.python import build_stale
    from cosim.run.simulate import run_scenario

    build_stale()
    t0 = time.perf_counter()
    result = run_scenario(find_scenario(name), build=False, plot=False)
    wall = time.perf_counter() - t0
    s = result.summary
    return {"real_time_factor": float(result.sim_time_s) / wall, "wall_s": wall,
            "lmi_median_ms": 1e3 * float(s["qp_solve_time_median_s"]),
            "lmi_total_s": float(s["qp_solve_time_total_s"]),
            "speed_mse_kmh2": s["speed_mse_kmh2"]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=int, default=600)
    ap.add_argument("--every", type=int, default=5)
    ap.add_argument("--no-scenario", action="store_true")
    args = ap.parse_args()
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    ctl, problems = record_problems(args.seconds)
    t = np.array(ctl.law.timing.recent) * 1e3  # the latest 1001 events (SolveTimes)
    c = np.array(ctl.law.timing.recent_cpu) * 1e3
    print(f"closed loop (cores, eco, {args.seconds} s): LMI per event wall median "
          f"{np.median(t):.2f} ms, p99 {np.percentile(t, 99):.2f} ms; CPU median "
          f"{np.median(c):.2f} ms, p99 {np.percentile(c, 99):.2f} ms; failures "
          f"{ctl.law.lmi_failures}")
    for solver, r in replay(ctl, problems, args.every).items():
        extra = (f", largest |F_scs - F_clarabel| / |F_clarabel| {r['max_rel_gain_diff']:.1e}"
                 if "max_rel_gain_diff" in r else "")
        print(f"replay {solver:<9} {r['solves']} LMIs: wall median {r['median_ms']:.2f} ms, p99 "
              f"{r['p99_ms']:.2f} ms; CPU median {r['cpu_median_ms']:.2f} ms, p99 "
              f"{r['cpu_p99_ms']:.2f} ms; failures {r['failures']}{extra}")
    if not args.no_scenario:
        r = scenario()
        print(f"scenario seed003_crh3_lmimpc_eco: {r['real_time_factor']:.1f} x real time "
              f"({r['wall_s']:.1f} s wall), LMI median {r['lmi_median_ms']:.2f} ms, LMI total "
              f"{r['lmi_total_s']:.1f} s, speed MSE {r['speed_mse_kmh2']:.4f} (km/h)^2")
    print(f"load average {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
