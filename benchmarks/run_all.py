"""Every benchmark against the reference it is measured against, in the same run (issue 10).

Prints one row per figure: the figure, the reference measured in this run, their ratio and the
issue's target, and writes them to ``benchmarks/results.json``. Asserts nothing.

* freight / EMU closed loop: the event-driven master on the scenario's FMUs (real-time factor)
  vs the minimal hand-written fmpy loop on the same FMUs (``raw_loop.py``); ratio = master
  wall / raw wall;
* freight / EMU plant: the compiled kernel (core, no FMI) replaying the closed loop's inputs vs
  the numpy reference path on the same inputs; ratio = numpy wall / kernel wall;
* RMPC N = 10 QP step (update + solve + result, median over the recorded QPs) with DAQP vs
  DAQP's update + solve alone; and OSQP's whole step;
* a further FMU instance (instantiate + initialise) vs the first instance in the process;
* seed 003's robust MPC: the LMI problem of an event (median over the closed loop's problems,
  replayed) with Clarabel vs SCS, and the eco scenario's real-time factor (``bench_seed003``).

    python benchmarks/run_all.py [--quick]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path[:0] = [str(ROOT), str(HERE), str(ROOT / "tests")]

import bench_freight  # noqa: E402
import bench_instances  # noqa: E402
import bench_mpc  # noqa: E402
import bench_plants  # noqa: E402
import bench_seed003  # noqa: E402
from raw_loop import raw_fmpy_loop  # noqa: E402

from cosim.fmu.build import build_stale  # noqa: E402
from cosim.run.master import run_scenario  # noqa: E402

FREIGHT, EMU = "seed002_freight_pid", "seed001_emu_pid"


def closed_loop(scenario: str, repeat: int) -> tuple[dict, object]:
    """Master vs raw fmpy loop on one scenario (medians of ``repeat`` runs)."""
    walls, raws, result = [], [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        result = run_scenario(ROOT / "scenarios" / f"{scenario}.toml", build=False, plot=False)
        walls.append(time.perf_counter() - t0)
        raws.append(raw_fmpy_loop(scenario)["wall_s"])
    sim = float(result.sim_time_s)
    wall, raw = statistics.median(walls), statistics.median(raws)
    return {"figure": sim / wall, "unit": "x real time", "reference": sim / raw,
            "reference_name": "minimal fmpy loop, same FMUs (x real time)",
            "ratio": wall / raw, "ratio_name": "master wall / fmpy loop wall"}, result


def freight_plant(result, repeat: int) -> dict:
    sim = float(result.sim_time_s)
    inputs = result.frame[["controller.force_demand", "controller.pipe_reduction"]].to_numpy()
    inputs = inputs[: int(round(sim / bench_freight.STEP))]
    fast = statistics.median(bench_freight.plant_core(inputs) for _ in range(repeat))
    ref = statistics.median(bench_freight.plant_core(inputs, kernel=False) for _ in range(1))
    substeps = sim / 0.01
    return {"figure": fast / substeps * 1e6, "unit": "us per 0.01 s sub-step (kernel, core)",
            "reference": ref / substeps * 1e6, "reference_name": "numpy reference path (us)",
            "ratio": ref / fast, "ratio_name": "numpy / kernel"}


def emu_plant(result, repeat: int) -> dict:
    sc, _, ctl = bench_plants._plant_setup(EMU)
    step = float(ctl.sample_time or sc.simulation.base_step)
    frame = result.frame
    n = len([c for c in frame.columns if c.startswith("plant.applied_force[")])
    times = np.arange(0.0, sc.simulation.stop_time - 1e-9, step)
    idx = np.searchsorted(frame["time"].to_numpy(), times, side="right") - 1
    forces = np.column_stack([frame[f"plant.applied_force[{i + 1}]"].to_numpy()[idx]
                              for i in range(n)])
    fast = statistics.median(bench_plants.plant_core_run(EMU, forces, step)
                             for _ in range(repeat))
    ref = bench_plants.plant_core_run(EMU, forces, step, kernel=False)
    sim = len(times) * step
    return {"figure": sim / fast, "unit": "x real time (plant core with outputs, kernel)",
            "reference": sim / ref, "reference_name": "numpy reference path (x real time)",
            "ratio": ref / fast, "ratio_name": "numpy / kernel"}


def qp(repeat: int) -> dict:
    r = bench_mpc.qp_step(10, repeat)
    return {"figure": r["daqp_step_us"], "unit": "us median, DAQP whole step",
            "reference": r["daqp_solver_alone_us"], "reference_name": "DAQP update+solve alone",
            "ratio": r["daqp_step_us"] / r["daqp_solver_alone_us"],
            "ratio_name": "step / solver alone", "osqp_step_us": r["osqp_step_us"],
            "daqp_max_iterations": r["daqp_max_iterations"]}


def instances() -> dict:
    rows = bench_instances.fresh_process_times(bench_instances.DEFAULT)
    worst = max(rows, key=lambda n: rows[n]["further_ms"])
    return {"figure": rows[worst]["further_ms"], "unit": f"ms, worst FMU ({worst})",
            "reference": 1e3 * rows[worst]["first_s"],
            "reference_name": "first instance in a fresh process (ms)",
            "ratio": rows[worst]["further_ms"] / (1e3 * rows[worst]["first_s"]),
            "ratio_name": "further / first", "per_fmu": rows}


def seed003_lmi(quick: bool) -> dict:
    ctl, problems = bench_seed003.record_problems(150 if quick else 600)
    r = bench_seed003.replay(ctl, problems, 5)
    sc = bench_seed003.scenario()
    return {"figure": r["clarabel"]["median_ms"], "unit": "ms median per event, Clarabel "
            "(replayed closed-loop LMIs)", "reference": r["scs"]["median_ms"],
            "reference_name": "SCS at 1e-4 on the same LMIs (ms)",
            "ratio": r["scs"]["median_ms"] / r["clarabel"]["median_ms"],
            "ratio_name": "SCS / Clarabel", "clarabel_p99_ms": r["clarabel"]["p99_ms"],
            "scs_p99_ms": r["scs"]["p99_ms"], "scs_failures": r["scs"]["failures"],
            "scs_max_rel_gain_diff": r["scs"]["max_rel_gain_diff"],
            "scenario_real_time_factor": sc["real_time_factor"],
            "scenario_lmi_median_ms": sc["lmi_median_ms"]}


TARGETS = {"freight closed loop": ">= 500 x real time", "EMU closed loop": ">= 1000 x real time",
           "RMPC N=10 QP step": "<= 35 us", "further FMU instance": "<= 10 ms",
           "freight plant kernel": "", "EMU plant kernel": "",
           "seed 003 RMPC LMI event": "<= 20 ms median"}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="one repetition each")
    parser.add_argument("--out", type=Path, default=HERE / "results.json")
    args = parser.parse_args()
    repeat = 1 if args.quick else 3
    build_stale()
    rows: dict[str, dict] = {}
    rows["freight closed loop"], freight_result = closed_loop(FREIGHT, repeat)
    rows["freight plant kernel"] = freight_plant(freight_result, repeat)
    rows["EMU closed loop"], emu_result = closed_loop(EMU, repeat)
    rows["EMU plant kernel"] = emu_plant(emu_result, repeat)
    rows["RMPC N=10 QP step"] = qp(20 if repeat > 1 else 5)
    rows["further FMU instance"] = instances()
    rows["seed 003 RMPC LMI event"] = seed003_lmi(args.quick)
    print(f"{'benchmark':<22} {'figure':>10}  {'reference':>10}  {'ratio':>7}  target / units")
    for name, r in rows.items():
        r["target"] = TARGETS[name]
        print(f"{name:<22} {r['figure']:>10.1f}  {r['reference']:>10.1f}  {r['ratio']:>7.2f}  "
              f"{r['target'] or '-'}; {r['unit']}; ref: {r['reference_name']}; "
              f"ratio: {r['ratio_name']}")
    meta = {"python": platform.python_version(), "machine": platform.machine(),
            "cpus": os.cpu_count(), "load_average": os.getloadavg(),
            "date_utc": time.strftime("%Y-%m-%d %H:%M:%S", time.gmtime())}
    args.out.write_text(json.dumps({"meta": meta, "benchmarks": rows}, indent=1,
                                   default=float) + "\n")
    print(f"wrote {args.out} (load average {meta['load_average'][0]:.1f} on {meta['cpus']} "
          "cores: figures scale with it)")


if __name__ == "__main__":
    main()
