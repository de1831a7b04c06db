"""Every benchmark against the reference it is measured against, in the same run.

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
* the freight kernel in numba vs the same kernel in C built with gcc (``bench_kernels.py``);
  ratio = C / numba;
* the master's loop vs the minimal fmpy loop on seed000_stop_pid, the freight and the EMU
  scenario (``bench_master.py``, alternating pairs; CPU-time and whole-run ratios beside);
* ``cosim run`` in its child process vs the same run in-process on seed000_stop_pid and the
  freight scenario (``bench_isolation.py``, alternating pairs; CPU counts the child's);
* ``cosim sweep seed000_stop_rmpc seed000_stop_rsmpc --set controller.N=3..15`` with 2 workers
  vs 1 (``bench_sweep.py``, end to end, load averages before and after).

The closed-loop rows also give CPU times (``time.process_time``: less sensitive to the load
than the wall time on a shared machine) and, per communication step, the CPU time of the
plant's doStep, of the controller (its event runs when its outputs are read) and of the FMI
calls around them in the fmpy loop, and the master's overhead (its CPU time minus plant and
controller).
* seed 001's claims campaign at K seeds (main and perturbed floating-point path) with 2
  workers vs 1 and on a 2-worker local Dask cluster vs 1 worker (``bench_campaign.py``, one
  run, load averages before and after);
* seed 003's robust MPC: the LMI problem of an event (median over the closed loop's problems,
  replayed) with Clarabel vs SCS, and the eco scenario's real-time factor (``bench_seed003``);
* ``cosim build --native --fmi all`` end to end: its wall time vs its CPU time (the command's
  and its compilers'; what one core would take), ratio = CPU / wall (``bench_native``);
* ``cosim reproduce seed000`` and ``seed004 --seeds 5`` (``--baseline-entries``: other
  entries) on this tree vs on 8a1e303 checked out beside it, alternating
  (``bench_baseline.py``): wall and CPU seconds, ratio = 8a1e303 / this tree, and whether
  every claim's verdict and k of K are the same; a baseline row of another entry, K or commit
  stays in ``results.json`` until measured again;
* the EMU and freight closed loops on their native FMUs through the master vs the bare C loop
  on the same FMUs (``bench_c_limit.py``, alternating): ratio = C loop wall / master loop wall
  (the share of the C loop's speed the master reaches), the final positions compared.

    python benchmarks/run_all.py [--quick] [--only campaign ...] [--campaign-seeds K]
        [--baseline COMMIT] [--baseline-seeds K] [--baseline-entries ENTRY ...]

``--only``: measure only the named groups (``closed_loop``, ``kernels``, ``qp``, ``instances``,
``master``, ``isolation``, ``sweep``, ``campaign``, ``seed003``, ``native_build``,
``baseline``, ``c_limit``) and keep the other rows of the existing ``results.json``; each row
records when it was measured and the load average then.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import re
import statistics
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path[:0] = [str(ROOT), str(HERE), str(ROOT / "tests")]

import bench_baseline  # noqa: E402
import bench_c_limit  # noqa: E402
import bench_campaign  # noqa: E402
import bench_freight  # noqa: E402
import bench_instances  # noqa: E402
import bench_isolation  # noqa: E402
import bench_kernels  # noqa: E402
import bench_master  # noqa: E402
import bench_mpc  # noqa: E402
import bench_native  # noqa: E402
import bench_plants  # noqa: E402
import bench_seed003  # noqa: E402
import bench_sweep  # noqa: E402
from raw_loop import raw_fmpy_loop  # noqa: E402

from cosim import site  # noqa: E402
from cosim.build.python import build_stale  # noqa: E402
from cosim.run.scenario import find_scenario  # noqa: E402
from cosim.run.simulate import run_scenario  # noqa: E402

FREIGHT, EMU = "seed002_freight_pid", "seed001_emu_pid"


def closed_loop(scenario: str, repeat: int) -> tuple[dict, object]:
    """Master vs raw fmpy loop on one scenario (medians of ``repeat`` runs), with the CPU
    time of each (less sensitive to the load than the wall time) and where the raw loop's
    CPU time goes: plant doStep, controller (its event runs when its outputs are read, so
    getReal of the controller plus its doStep), and the FMI calls around them."""
    walls, cpus, raws, raw_cpus, result = [], [], [], [], None
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        result = run_scenario(find_scenario(scenario), build=False, plot=False)
        walls.append(time.perf_counter() - t0)
        cpus.append(time.process_time() - c0)
        raw = raw_fmpy_loop(scenario)
        raws.append(raw["wall_s"])
        raw_cpus.append(raw["cpu_s"])
    sim = float(result.sim_time_s)
    wall, raw = statistics.median(walls), statistics.median(raws)
    cpu, raw_cpu = statistics.median(cpus), statistics.median(raw_cpus)
    parts = raw_fmpy_loop(scenario, split=True)["split_cpu_s"]
    steps = float(result.summary["do_steps"]["plant"])  # communication steps
    plant = sum(v for k, v in parts.items() if k == "doStep plant")
    controller = sum(v for k, v in parts.items()
                     if k == "doStep controller" or k.startswith("getReal controller"))
    split = {"plant_doStep_us": plant / steps * 1e6,
             "controller_us": controller / steps * 1e6,
             "fmi_calls_us": (sum(parts.values()) - plant - controller) / steps * 1e6,
             "master_cpu_us": cpu / steps * 1e6, "raw_loop_cpu_us": raw_cpu / steps * 1e6}
    split["master_overhead_us"] = split["master_cpu_us"] - split["plant_doStep_us"] \
        - split["controller_us"]
    return {"figure": sim / wall, "unit": "x real time", "reference": sim / raw,
            "reference_name": "minimal fmpy loop, same FMUs (x real time)",
            "ratio": wall / raw, "ratio_name": "master wall / fmpy loop wall",
            "cpu_real_time_factor": sim / cpu, "raw_loop_cpu_real_time_factor": sim / raw_cpu,
            "per_step_cpu_us": split}, result


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


def freight_kernel_c(repeat: int) -> dict:
    """The freight kernel in numba vs the same kernel in C (gcc), cruise and brake wave."""
    rows = bench_kernels.run(repeat)
    if not rows:
        return {"figure": float("nan"), "unit": "us per sub-step (numba)",
                "reference": float("nan"), "reference_name": "C kernel (gcc): not available",
                "ratio": float("nan"), "ratio_name": "C / numba"}
    cruise = rows[0]
    return {"figure": cruise["numba_us_per_substep"],
            "unit": "us per sub-step, numba kernel (cruise)",
            "reference": cruise["c_us_per_substep"],
            "reference_name": "the same kernel in C, gcc -O2 (us)",
            "ratio": cruise["c_over_numba"], "ratio_name": "C / numba", "cases": rows}


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


def master_overhead(scenario: str, repeat: int) -> dict:
    """The master's loop against the minimal fmpy loop, alternating pairs (bench_master)."""
    r = bench_master.master_vs_raw(scenario, repeat)
    return {"figure": r["master_loop_s"], "unit": "s, master loop (communication points)",
            "reference": r["raw_loop_s"], "reference_name": "minimal fmpy loop, same FMUs (s)",
            "ratio": r["loop_ratio"], "ratio_name": "master / fmpy loop, wall (median of pairs)",
            "cpu_ratio": r["loop_cpu_ratio"], "whole_run_ratio": r["run_ratio"],
            "load_average": r["load_average"]}


def sweep_speedup(repeat: int) -> dict:
    """``cosim sweep seed000_stop_rmpc seed000_stop_rsmpc --set controller.N=3..15``, 2 vs 1
    workers (bench_sweep)."""
    r = bench_sweep.speedup(repeat)
    return {"figure": r["workers_2_s"], "unit": "s, --workers 2 (end to end)",
            "reference": r["workers_1_s"], "reference_name": "--workers 1 (s)",
            "ratio": r["speedup"], "ratio_name": "speed-up, workers 1 / workers 2",
            "cpu_s": {"workers_1": r["workers_1_cpu_s"], "workers_2": r["workers_2_cpu_s"]},
            "cold_design_cache_s": {"workers_1": r["cold_workers_1_s"],
                                    "workers_2": r["cold_workers_2_s"],
                                    "speedup": r["cold_speedup"]},
            "load_average": [r["load_before"], r["load_after"]]}


def isolation_overhead(scenario: str, repeat: int) -> dict:
    """``cosim run``'s child process against the same run in-process (bench_isolation)."""
    r = bench_isolation.isolated_vs_in_process(scenario, repeat)
    return {"figure": r["isolated_s"], "unit": "s, run in a child process (no plot)",
            "reference": r["in_process_s"], "reference_name": "the same run in-process (s)",
            "ratio": r["ratio"], "ratio_name": "isolated / in-process, wall (median of pairs)",
            "cpu_ratio": r["cpu_ratio"], "extra_ms": r["extra_ms"],
            "load_average": r["load_average"]}


def campaign_speedups(seeds: int) -> dict[str, dict]:
    """seed 001's claims at K = ``seeds`` (with the rounding rerun): 2 local workers vs 1 and
    a 2-worker local Dask cluster vs 1 worker, in one run (bench_campaign)."""
    r = bench_campaign.campaign(seeds)
    what = f"K = {seeds}, {r['runs']} runs"
    common = {"reference": r["1 worker"], "reference_name": f"1 worker (s; {what})",
              "load_average": [r["load_before"], r["load_after"]], "seeds": seeds,
              "cpu_s": {label: r[f"{label} cpu"] for label, _, _ in bench_campaign.WAYS}}
    return {"campaign 2 vs 1 workers": {
                "figure": r["2 workers"], "unit": "s, seed001 claims, --workers 2", **common,
                "ratio": r["speedup_2_workers"], "ratio_name": "speed-up, 1 worker / 2",
                "cpu_ratio": r["1 worker cpu"] / r["2 workers cpu"]},
            "campaign Dask 2 vs 1 worker": {
                "figure": r["dask 2 workers"], "unit": "s, seed001 claims, local Dask x 2",
                **common, "ratio": r["speedup_dask"],
                "ratio_name": "speed-up, 1 worker / Dask x 2",
                "cpu_ratio": r["1 worker cpu"] / r["dask 2 workers cpu"]}}


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


def native_build() -> dict:
    """``cosim build --native --fmi all`` (bench_native.build_all): wall time against the CPU
    time of the command and its compilers."""
    r = bench_native.build_all()
    return {"figure": r["wall_s"], "unit": f"s wall, {r['fmus']} FMUs (FMI 2.0 and 3.0, "
            + ("Linux and Windows binaries)" if r["windows"] else "Linux binaries)"),
            "reference": r["cpu_s"], "reference_name": "CPU time of the build and compilers (s)",
            "ratio": r["cpu_s"] / r["wall_s"], "ratio_name": "CPU / wall (cores used)",
            "load_average": [r["load_before"], r["load_after"]]}


def baseline_row_name(entry: str, seeds: int, commit: str, same_entry: bool = False) -> str:
    return f"campaign {entry} K={seeds} vs {commit}" + (" on its entry" if same_entry else "")


BASELINE_ROW = re.compile(r"campaign \S+ K=\d+ vs \S+( on its entry)?")  # a baseline_row_name


def verdict_agreement(claims: int, differences: list[dict]) -> str:
    """How the verdicts of the ``claims`` claims both trees have compare, from
    :func:`bench_baseline.verdict_differences`: in how many k of K differs (the simulations
    gave other outcomes) and in how many only the verdict's label (the same k of K, read by
    other statistics)."""
    this, base = bench_baseline.THIS, bench_baseline.BASE
    k_differs = sum(d[this][1] != d[base][1] for d in differences)
    labels = len(differences) - k_differs
    return (f"of the {claims} claims of both trees, k of K differs in {k_differs} and the "
            f"verdict's label alone (the same k of K) in {labels}")


def baseline_campaigns(commit: str, seeds: int, quick: bool,
                       entries: list[str] | None = None, same_entry: bool = False
                       ) -> dict[str, dict]:
    """``cosim reproduce ENTRY --seeds K`` for each of ``entries`` (default
    :data:`bench_baseline.ENTRIES`) on this tree vs ``commit`` checked out beside it,
    alternating (bench_baseline; one pair per entry with ``quick``, else two; ``same_entry``:
    this tree runs ``commit``'s entry file)."""
    rows = {}
    results = bench_baseline.compare(list(entries or bench_baseline.ENTRIES), commit, seeds,
                                     1 if quick else 2, same_entry=same_entry)
    for entry, r in results.items():
        this, base = bench_baseline.THIS, bench_baseline.BASE
        which = f"{commit}'s entry file for {entry}" if same_entry else entry
        pins = (f" ({len({k for v in r['pinned'].values() for k in v})} controller or plant "
                f"parameters set to {commit}'s defaults in {len(r['pinned'])} of its runs)"
                if r["pinned"] else "")
        numbers = (f"; the members' medians ({', '.join(r['numbers_compared'])}) differ in "
                   f"{len(r['number_differences'])} claims") if r["numbers_compared"] else ""
        check = r["python_check"]
        if check is not None:
            numbers += (f"; this tree on its Python builds (the baseline's; untimed): k of K or "
                        f"verdict differ from {commit}'s in "
                        f"{len(check['verdict_differences_from_baseline'])} claims and medians "
                        f"in {len(check['number_differences_from_baseline'])}; from this "
                        f"tree's native run in {len(check['verdict_differences_from_native'])}, "
                        f"the verdict's label in {check['label_differences_from_native']}")
        rows[baseline_row_name(entry, seeds, commit, same_entry)] = {
            "figure": r["wall_s"][this], "unit": f"s wall, this tree, cosim reproduce {which} "
            f"--seeds {seeds}{pins}; {verdict_agreement(r['claims'], r['verdict_differences'])}"
            f"{numbers}",
            "reference": r["wall_s"][base],
            "reference_name": f"{commit} checked out beside it (s wall)",
            "ratio": r["ratio_wall"], "ratio_name": f"{commit} / this tree, wall",
            "cpu_s": r["cpu_s"], "cpu_ratio": r["ratio_cpu"], "claims": r["claims"],
            "same_verdicts": r["same_verdicts"],
            "verdict_differences": r["verdict_differences"], "only_this": r["only_this"],
            "only_baseline": r["only_baseline"], "repeat": r["repeat"],
            "same_entry": same_entry, "pinned": r["pinned"], "python_check": check,
            "number_differences": r["number_differences"],
            "numbers_compared": r["numbers_compared"],
            "load_average": r["load_average"]}
    return rows


def c_limit(label: str, repeat: int) -> dict:
    """The master vs the bare C loop on the native FMUs of ``label``'s scenario
    (bench_c_limit, alternating pairs)."""
    r = bench_c_limit.master_vs_c(bench_c_limit.SCENARIOS[label], repeat)
    same = "the same as" if r["same_final_position"] else "NOT the same as"
    return {"figure": r["master_loop_s"],
            "unit": f"s, master loop, native FMUs; final position {same} the C loop's",
            "reference": r["c_loop_s"], "reference_name": "bare C loop, same FMUs (s)",
            "ratio": r["c_over_master"],
            "ratio_name": "C loop wall / master wall (share of the C loop's speed)",
            "cpu_ratio": r["c_over_master_cpu"],
            "master_over_c": r["master_loop_s"] / r["c_loop_s"],
            "master_over_c_cpu": r["master_loop_cpu_s"] / r["c_loop_cpu_s"],
            "same_final_position": r["same_final_position"],
            "final_position_m": {"master": r["master_final_position"],
                                 "c_loop": r["c_final_position"]},
            "load_average": r["load_average"]}


GROUPS = ("closed_loop", "kernels", "qp", "instances", "master", "isolation", "sweep", "campaign",
          "seed003", "native_build", "baseline", "c_limit")


def baseline_target(commit: str) -> str:
    return f"<= {1 / bench_baseline.TARGET:g} of {commit}'s time"

TARGETS = {"freight closed loop": ">= 500 x real time", "EMU closed loop": ">= 1000 x real time",
           "RMPC N=10 QP step": "<= 35 us", "further FMU instance": "<= 10 ms",
           "freight plant kernel": "", "EMU plant kernel": "", "freight kernel C vs numba": "",
           "master/raw seed000_stop_pid": "ratio <= 1.10", "master/raw seed002_freight_pid": "",
           "master/raw seed001_emu_pid": "",
           **{f"isolated/in-process {name}": "" for name in bench_isolation.SCENARIOS},
           "sweep 2 vs 1 workers": "speed-up >= 1.7",
           "campaign 2 vs 1 workers": "speed-up >= 1.8",
           "campaign Dask 2 vs 1 worker": "speed-up >= 1.8",
           "seed 003 RMPC LMI event": "<= 20 ms median",
           "native build, all FMUs": "<= 60 s on 2 cores",
           **{baseline_row_name(e, bench_baseline.SEEDS, bench_baseline.BASELINE):
              baseline_target(bench_baseline.BASELINE)
              for e in bench_baseline.ENTRIES},
           **{f"{label} master vs bare C loop":
              f">= {bench_c_limit.TARGET:g} of the C loop's speed"
              for label in bench_c_limit.SCENARIOS}}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="one repetition each")
    parser.add_argument("--out", type=Path, default=HERE / "results.json")
    parser.add_argument("--only", nargs="+", choices=GROUPS, default=list(GROUPS),
                        help="measure these groups only; keep the other rows of --out")
    parser.add_argument("--campaign-seeds", type=int, default=20,
                        help="K of the campaign benchmark (default 20)")
    parser.add_argument("--baseline", default=bench_baseline.BASELINE,
                        help=f"the commit of the baseline group (default "
                        f"{bench_baseline.BASELINE})")
    parser.add_argument("--baseline-seeds", type=int, default=bench_baseline.SEEDS,
                        help=f"K of the baseline group (default {bench_baseline.SEEDS})")
    parser.add_argument("--baseline-entries", nargs="+", default=list(bench_baseline.ENTRIES),
                        help=f"the entries of the baseline group (default "
                        f"{' '.join(bench_baseline.ENTRIES)})")
    parser.add_argument("--baseline-same-entry", action="store_true",
                        help="this tree runs the baseline's entry files in the baseline group "
                        "(the same claims and members on both trees)")
    args = parser.parse_args()
    repeat = 1 if args.quick else 3
    build_stale()
    rows: dict[str, dict] = {}
    if set(args.only) != set(GROUPS) and args.out.is_file():
        rows = json.loads(args.out.read_text()).get("benchmarks", {})
    measured: dict[str, dict] = {}
    only = set(args.only)
    if "closed_loop" in only or "kernels" in only:
        measured["freight closed loop"], freight_result = closed_loop(FREIGHT, repeat)
        measured["EMU closed loop"], emu_result = closed_loop(EMU, repeat)
    if "kernels" in only:
        measured["freight plant kernel"] = freight_plant(freight_result, repeat)
        measured["freight kernel C vs numba"] = freight_kernel_c(2000 if repeat > 1 else 500)
        measured["EMU plant kernel"] = emu_plant(emu_result, repeat)
    if "qp" in only:
        measured["RMPC N=10 QP step"] = qp(20 if repeat > 1 else 5)
    if "instances" in only:
        measured["further FMU instance"] = instances()
    if "master" in only:
        for scenario in bench_master.SCENARIOS:
            measured[f"master/raw {scenario}"] = master_overhead(
                scenario, repeat if scenario == FREIGHT or scenario == EMU else 5 * repeat)
    if "isolation" in only:
        for scenario in bench_isolation.SCENARIOS:
            measured[f"isolated/in-process {scenario}"] = isolation_overhead(scenario,
                                                                             5 * repeat)
    if "sweep" in only:
        measured["sweep 2 vs 1 workers"] = sweep_speedup(5 if repeat > 1 else 1)  # noisy
    if "campaign" in only:
        measured.update(campaign_speedups(args.campaign_seeds))
    if "seed003" in only:
        measured["seed 003 RMPC LMI event"] = seed003_lmi(args.quick)
    if "native_build" in only:
        measured["native build, all FMUs"] = native_build()
    if "baseline" in only:
        measured.update(baseline_campaigns(args.baseline, args.baseline_seeds, args.quick,
                                           args.baseline_entries, args.baseline_same_entry))
    if "c_limit" in only:
        for label in bench_c_limit.SCENARIOS:
            measured[f"{label} master vs bare C loop"] = c_limit(label, repeat)
    stamp = time.strftime("%Y-%m-%d %H:%M:%S", time.gmtime())
    for r in measured.values():
        r.setdefault("measured_utc", stamp)
        r.setdefault("load_average", os.getloadavg()[0])
    rows.update(measured)
    # a baseline row of another commit, K or entry: its stored target, this run's if measured
    targets = {**TARGETS, **{name: rows[name].get("target") or baseline_target(args.baseline)
                             for name in rows
                             if name not in TARGETS and BASELINE_ROW.fullmatch(name)}}
    rows = {name: rows[name] for name in targets if name in rows}  # the table's order
    print(f"{'benchmark':<30} {'figure':>10}  {'reference':>10}  {'ratio':>7}  target / units")
    for name, r in measured.items():
        r["target"] = targets[name]
        print(f"{name:<30} {r['figure']:>10.1f}  {r['reference']:>10.1f}  {r['ratio']:>7.2f}  "
              f"{r['target'] or '-'}; {r['unit']}; ref: {r['reference_name']}; "
              f"ratio: {r['ratio_name']}")
        if "per_step_cpu_us" in r:
            split = ", ".join(f"{k} {v:.0f}" for k, v in r["per_step_cpu_us"].items())
            print(f"{'':<30} CPU: {r['cpu_real_time_factor']:.0f} x real time (master), "
                  f"{r['raw_loop_cpu_real_time_factor']:.0f} x (fmpy loop); per step (us): "
                  f"{split}")
        if "same_verdicts" in r:
            print(f"{'':<30} CPU ratio {r['cpu_ratio']:.2f}; same verdicts and k of K: "
                  f"{r['same_verdicts']} ({r['claims']} claims on both trees; "
                  f"{len(r['only_this'])} on this tree only, {len(r['only_baseline'])} on the "
                  "baseline only)")
            for d in r["verdict_differences"]:
                print(f"{'':<30} {d['id']}: this tree {d[bench_baseline.THIS]}, baseline "
                      f"{d[bench_baseline.BASE]}")
            if r.get("numbers_compared"):
                print(f"{'':<30} members' medians differ in: "
                      f"{', '.join(r['number_differences']) or 'no claim'}")
        if "same_final_position" in r:
            print(f"{'':<30} CPU ratio {r['cpu_ratio']:.2f}; final position "
                  f"{r['final_position_m']['master']:.17g} m (master), "
                  f"{r['final_position_m']['c_loop']:.17g} m (C): same "
                  f"{r['same_final_position']}")
        for case in r.get("cases", ()):
            print(f"{'':<30} {case['case']}: numba {case['numba_us_per_substep']:.2f}, C "
                  f"{case['c_us_per_substep']:.2f}, numpy {case['numpy_us_per_substep']:.1f} "
                  f"us/sub-step; max rel. diff numba-C {case['max_rel_diff_numba_c']:.1e}")
    meta = {"python": platform.python_version(), "machine": platform.machine(),
            "cpus": os.cpu_count(), "load_average": os.getloadavg(), "date_utc": stamp}
    if set(args.only) != set(GROUPS) and args.out.is_file():  # a partial update
        meta = {**json.loads(args.out.read_text()).get("meta", {}),
                "updated_utc": stamp, "updated_groups": ", ".join(args.only)}
    args.out.write_text(json.dumps({"meta": meta, "benchmarks": rows}, indent=1,
                                   default=float) + "\n")
    print(f"wrote {args.out} (load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} "
          "cores: figures scale with it)")
    if args.out == site.BENCHMARKS_JSON:  # the site's page follows its source
        page = site.DOCS / "benchmarks.md"
        page.write_text(site.benchmarks_page(args.out))
        print(f"wrote {page}")


if __name__ == "__main__":
    main()
