"""Benchmark of the seed 000 predictive controllers (prints figures, asserts nothing).

1. QP time per controller event (median and 99th percentile, wall time of vector update +
   solve + result, summed over the QPs of one event; RSMPC solves up to N-1 QPs per event) for
   N = 5, 10, 15, from a direct closed loop of the plant and controller cores; then the RMPC
   N = 10 QP step on the recorded QPs with DAQP and OSQP and DAQP's solve alone.
2. Whole-scenario wall time per controller through the event-driven master (FMUs).

    python benchmarks/bench_mpc.py [--repeat 3]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path[:0] = [str(ROOT), str(ROOT / "tests")]

from mpc_loop import run_loop  # noqa: E402

from controllers.mpc.stop_mpc import (  # noqa: E402
    IdealStopMpc,
    SelfTriggeredStopMpc,
    StopMpcParams,
    TubeStopMpc,
)

CONTROLLERS = {"MPC": IdealStopMpc, "RMPC": TubeStopMpc, "RSMPC": SelfTriggeredStopMpc}
SCENARIOS = {"PID": "seed000_stop_pid", "MPC": "seed000_stop_mpc",
             "RMPC": "seed000_stop_rmpc", "RSMPC": "seed000_stop_rsmpc"}


def qp_table(repeat: int) -> None:
    print("QP time per controller event (direct core loop, 60 s scenario)")
    print(f"{'controller':<8} {'N':>3} {'events':>7} {'QPs':>6} {'median ms':>10} "
          f"{'p99 ms':>8} {'per QP ms':>10} {'stop err m':>11}")
    for name, cls in CONTROLLERS.items():
        for N in (5, 10, 15):
            times: list[float] = []
            solves = events = 0
            per_qp: list[float] = []
            for _ in range(repeat):
                p = replace(StopMpcParams(), horizon=N)
                core = cls(p)
                for hold in range(1, core.max_hold + 1):
                    core.qp(hold)  # build outside the timed region (done once per FMU)
                r = run_loop(core, p)
                ev = [x for x in core.timing.recent if x > 0.0]  # < WINDOW events
                times += ev
                solves += core.qp_solves
                events += len(ev)
                per_qp.append(sum(ev) / max(core.qp_solves, 1))
            arr = np.array(times) * 1e3
            print(f"{name:<8} {N:>3} {events // repeat:>7} {solves // repeat:>6} "
                  f"{np.median(arr):>10.3f} {np.percentile(arr, 99):>8.3f} "
                  f"{1e3 * statistics.mean(per_qp):>10.3f} {r.stop_error:>+11.3f}")


def record_qps(cls=TubeStopMpc, N: int = 10, solver: str = "daqp") -> list:
    """(qp, x0, ref, d, warm_x, warm_y) of every QP a closed loop of ``cls`` solved."""
    from controllers.common.qp import HorizonQP

    calls = []
    original = HorizonQP.solve

    def spy(self, x0, ref, d=None, warm_x=None, warm_y=None):
        calls.append((self, x0, ref, d, warm_x, warm_y))
        return original(self, x0, ref, d, warm_x, warm_y)

    p = replace(StopMpcParams(), horizon=N, qp_solver=solver)
    HorizonQP.solve = spy
    try:
        run_loop(cls(p), p)
    finally:
        HorizonQP.solve = original
    return calls


def qp_step(N: int = 10, repeat: int = 20) -> dict[str, float]:
    """Median over the recorded RMPC QPs (us): the whole step (update + solve + result) with
    DAQP and with OSQP, and DAQP's update + solve alone on the same data."""
    out: dict[str, float] = {}
    for solver in ("daqp", "osqp"):
        calls = record_qps(TubeStopMpc, N, solver)
        times, iters = [], []
        for _ in range(repeat if solver == "daqp" else max(1, repeat // 4)):
            for qp, x0, ref, d, wx, wy in calls:
                res = qp.solve(x0, ref, d, wx, wy)
                times.append(res.solve_time)
                iters.append(res.iterations)
        out[f"{solver}_step_us"] = 1e6 * float(np.median(times))
        out[f"{solver}_max_iterations"] = float(max(iters))
        if solver == "daqp":
            alone = []
            for _ in range(repeat):
                for qp, x0, ref, _, _, _ in calls:  # RMPC: no feedforward d
                    z = qp._W_nod @ np.concatenate((x0, ref.ravel()))
                    a, b = qp._split
                    low = qp._lo_all - z[b:]
                    high = np.maximum(qp._hi_all - z[b:], low)
                    t0 = time.perf_counter()
                    qp.solver.update(f=z[a:b], bupper=high, blower=low, sense=qp._cold)
                    qp.solver.solve()
                    alone.append(time.perf_counter() - t0)
            out["daqp_solver_alone_us"] = 1e6 * float(np.median(alone))
    return out


def scenario_table(repeat: int) -> None:
    from cosim.run.scenario import load_scenario
    from cosim.run.simulate import ensure_built, run_scenario

    print("\nWhole scenario through the event-driven master (60 s simulated, N = 10)")
    print(f"{'controller':<8} {'wall s (median)':>16} {'executions':>11} {'stop err m':>11}")
    for name, scenario in SCENARIOS.items():
        ensure_built(load_scenario(scenario))
        walls = []
        for _ in range(repeat):
            t0 = time.perf_counter()
            res = run_scenario(scenario, build=False, plot=False)
            walls.append(time.perf_counter() - t0)
        s = res.summary
        print(f"{name:<8} {statistics.median(walls):>16.3f} "
              f"{s['executions']['controller']:>11} {s['stop_error_m']:>+11.3f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    qp_table(args.repeat)
    r = qp_step(10)
    print(f"\nRMPC N = 10 whole QP step, median over the recorded QPs: DAQP "
          f"{r['daqp_step_us']:.1f} us (solver alone {r['daqp_solver_alone_us']:.1f} us, at most "
          f"{r['daqp_max_iterations']:.0f} iterations), OSQP {r['osqp_step_us']:.1f} us")
    scenario_table(args.repeat)


if __name__ == "__main__":
    main()
