"""Real-time factors of the native C plant FMUs against the Python FMUs, the Python cores and
the bare C kernel, in one run (prints figures, asserts nothing).

BrakeDelayTrain (seed 000):

* plant only: the seed-000 plant (scenario parameters of seed000_stop_pid) stepped over 60 s
  in 0.2-s communication steps with a fixed braking command, through the plant core (no FMI),
  the Python FMU and the native FMU (fmpy ``FMU2Slave``, one setReal/doStep/getReal per step);
* closed loop: every shipped seed-000 scenario through the event-driven master with the Python
  plant FMU and with the native one (the controllers are the Python FMUs in both).

FreightTrain (seed 002, HXD1 + 108 C80):

* plant only: the plant driven by the force demand and brake-pipe reduction the speed PID of
  seed002_freight_pid commands in its closed loop (recorded once, replayed open loop) over the
  whole run in 0.2-s steps, every output read after every step, through the core (numba
  kernel, no FMI), the Python FMU and the native FMU; and the bare C kernel
  (cosim/fmu/native/plants/freight_kernel.c through ctypes on the arguments of one communication
  step, as benchmarks/bench_kernels.py calls it): its time per sub-step times the run's
  sub-steps, the bound no FMU of this kernel can beat;
* closed loop: every shipped seed-002 scenario with the Python plant and controller FMUs, the
  native plant and the Python controller, and the native plant and controller (where the
  controller has a native build), in one run: whole-run real-time factors, their ratios to
  the all-Python loop, and where the wall time goes (each FMU, the rest: master and fmpy).

Crh3Train, Emu3, Emu8 (seeds 003, 001, 004), plant only: the Python FMU and the native FMU
stepped over the same simulated time with a fixed input, in the step and with the parameters
of the plant's shipped scenarios, through fmpy ``FMU2Slave`` (one setReal/doStep/getReal of
every output per step); their real-time factors and the ratio, in the same run.

Building: ``python -m cosim.cli build --native --fmi all`` end to end (every native FMU, FMI
2.0 and 3.0, the Linux and, with mingw-w64 installed, the Windows binaries): its wall time and
the CPU time of it and its compilers (the time one core would take), in one run
(:func:`build_all`; the ``native_build`` row of run_all.py).

    python benchmarks/bench_native.py [--repeat 3]
        [--plants freight freight_loops brake_delay crh3_emu build]
"""

from __future__ import annotations

import argparse
import os
import resource
import shutil
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from fmpy import extract, read_model_description  # noqa: E402
from fmpy.fmi2 import FMU2Slave  # noqa: E402

from cosim.build.native import NATIVE, build_native  # noqa: E402
from cosim.build.python import build_stale, catalog  # noqa: E402
from cosim.fmu.state import to_ticks  # noqa: E402
from cosim.run.scenario import find_scenario, load_scenario, scenario_files  # noqa: E402
from cosim.run.simulate import run_scenario  # noqa: E402
from plants.brake_delay import BrakeDelayTrain  # noqa: E402
from plants.freight import FreightTrain  # noqa: E402

STOP, STEP, COMMAND = 60.0, 0.2, 40.0


def plant_parameters() -> dict:
    sc = load_scenario(find_scenario("seed000_stop_pid"))
    return dict(sc.components["plant"].parameters)


def run_core(params: dict) -> float:
    values = {v.name: v.start for v in BrakeDelayTrain.declarations()
              if v.causality == "parameter"}
    values.update(params)
    t0 = time.perf_counter()
    core = BrakeDelayTrain.from_parameters(values, ROOT)
    for k in range(round(STOP / STEP)):
        core.advance(to_ticks(k * STEP), to_ticks(STEP), {"brake_command": COMMAND})
        core.outputs()
    return time.perf_counter() - t0


def run_fmu(path: Path, params: dict) -> float:
    md = read_model_description(str(path))
    unzipdir = extract(str(path))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    outs = [vr[n] for n in ("v", "s", "a", "a_c", "applied_command", "grade")]
    t0 = time.perf_counter()
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzipdir, instanceName="bench",
                    modelIdentifier=md.coSimulation.modelIdentifier)
    fmu.instantiate()
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    for name, value in params.items():
        (fmu.setString if isinstance(value, str) else fmu.setReal)([vr[name]], [value])
    fmu.exitInitializationMode()
    for k in range(round(STOP / STEP)):
        fmu.setReal([vr["brake_command"]], [COMMAND])
        fmu.doStep(k * STEP, STEP)
        fmu.getReal(outs)
    fmu.terminate()
    fmu.freeInstance()
    return time.perf_counter() - t0


def _clocks() -> tuple[float, float]:
    return time.perf_counter(), time.process_time()


def _since(start: tuple[float, float]) -> tuple[float, float]:
    """(wall, CPU) seconds since ``start``: CPU time is what the process itself spent, less
    sensitive than wall time to other processes on a shared machine."""
    wall, cpu = _clocks()
    return wall - start[0], cpu - start[1]


def _median(fn, repeat: int) -> tuple[float, float]:
    fn()  # warm-up (extraction, imports, kernel compilation or cache load)
    runs = [fn() for _ in range(repeat)]
    return (statistics.median(r[0] for r in runs), statistics.median(r[1] for r in runs))


def freight_inputs() -> tuple[float, dict, list[tuple[float, float]]]:
    """(step, plant parameters, (force demand, pipe reduction) per step) of the closed loop
    of seed002_freight_pid with the Python FMUs."""
    sc = load_scenario(find_scenario("seed002_freight_pid"))
    frame = run_scenario(sc, plot=False).frame
    demand = frame["controller.force_demand"].to_numpy()
    reduction = frame["controller.pipe_reduction"].to_numpy()
    # row k is the instant t_k: the inputs held over [t_k, t_k+1)
    steps = list(zip(demand[:-1].tolist(), reduction[:-1].tolist()))
    return sc.simulation.output_interval, dict(sc.components["plant"].parameters), steps


def freight_core(step: float, params: dict, inputs: list) -> tuple[float, float]:
    values = {v.name: v.start for v in FreightTrain.declarations()
              if v.causality == "parameter"}
    values.update(params)
    t0 = _clocks()
    core = FreightTrain.from_parameters(values, ROOT)
    for k, (demand, reduction) in enumerate(inputs):
        core.advance(to_ticks(k * step), to_ticks(step),
                     {"force_demand": demand, "pipe_reduction": reduction})
        core.outputs()
    return _since(t0)


def freight_fmu(path: Path, step: float, params: dict, inputs: list) -> tuple[float, float]:
    md = read_model_description(str(path))
    unzipdir = extract(str(path))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    outs = [v.valueReference for v in md.modelVariables if v.causality == "output"]
    ins = [vr["force_demand"], vr["pipe_reduction"]]
    t0 = _clocks()
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzipdir, instanceName="bench",
                    modelIdentifier=md.coSimulation.modelIdentifier)
    fmu.instantiate()
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    for name, value in params.items():
        (fmu.setString if isinstance(value, str) else fmu.setReal)([vr[name]], [value])
    fmu.exitInitializationMode()
    for k, (demand, reduction) in enumerate(inputs):
        fmu.setReal(ins, [demand, reduction])
        fmu.doStep(k * step, step)
        fmu.getReal(outs)
    fmu.terminate()
    fmu.freeInstance()
    return _since(t0)


def bare_kernel_per_substep(repeat: int) -> float:
    """Seconds per sub-step of the C kernel alone (cruise case of bench_kernels)."""
    import tempfile

    sys.path.insert(0, str(ROOT / "benchmarks"))
    import bench_kernels

    with tempfile.TemporaryDirectory() as tmp:
        dll = bench_kernels.build_c(Path(tmp))
        _, args = bench_kernels.captured_args("cruise")
        n_sub = args[4].size
        per_call = bench_kernels._timed(lambda a: bench_kernels.c_call(dll, a),
                                        lambda: tuple(a.copy() for a in args), 200 * repeat)
    return per_call / n_sub


def bench_freight(repeat: int) -> None:
    t0 = time.perf_counter()
    native = build_native("FreightTrain", windows=False)
    print(f"native build FreightTrain (linux64): {time.perf_counter() - t0:.2f} s")
    specs = catalog()
    build_stale([specs["FreightTrain"]])
    step, params, inputs = freight_inputs()
    stop = step * len(inputs)
    n_sub = round(stop / params.get("max_step", 0.01))
    rows = {
        "core (Python)": lambda: freight_core(step, params, inputs),
        "Python FMU": lambda: freight_fmu(specs["FreightTrain"].path, step, params, inputs),
        "native FMU": lambda: freight_fmu(native, step, params, inputs),
    }
    print(f"\nplant only, FreightTrain, {stop:g} s in {step:g}-s steps, inputs of "
          f"seed002_freight_pid (median of {repeat}):")
    medians = {name: _median(fn, repeat) for name, fn in rows.items()}
    kernel = bare_kernel_per_substep(repeat) * n_sub
    medians["bare C kernel"] = (kernel, kernel)
    print(f"  {'':14s} {'wall':>8s}   {'CPU':>8s}   real-time factor (wall, CPU)")
    for name, (wall, cpu) in medians.items():
        print(f"  {name:14s} {wall:8.3f} s {cpu:8.3f} s   {stop / wall:8.0f} {stop / cpu:8.0f}")
    for k, what in ((0, "wall"), (1, "CPU")):
        py, nat, bare = (medians[n][k] for n in ("Python FMU", "native FMU", "bare C kernel"))
        print(f"  {what}: native / Python FMU speed-up {py / nat:.2f}x; "
              f"native FMU time / bare C kernel time {nat / bare:.2f}")
    print()
    freight_loops(repeat)


#: the freight closed loop's configurations: (label, instances run native)
FREIGHT_LOOPS = (("Python plant + Python controller", ()),
                 ("native plant + Python controller", ("plant",)),
                 ("native plant + native controller", ("plant", "controller")))


def freight_loops(repeat: int, scenarios: list[str] | None = None) -> dict:
    """Every shipped seed-002 closed loop through the event master in the three
    configurations of :data:`FREIGHT_LOOPS` (the last where the controller has a native
    build), alternating, the first round a warm-up; median whole-run wall time, the plant's
    and the controller's FMU wall time and the rest (master and fmpy calls), and the
    real-time factors' ratios to the all-Python loop. Returns them by scenario."""
    print("closed loop, event master, seed 002: whole-run real-time factor (wall), the FMUs' "
          f"wall time and the rest (master + fmpy), median of {repeat}:")
    out = {}
    names = scenarios or [n for n in scenario_files() if n.startswith("seed002_")]
    for sc in names:
        scenario = load_scenario(find_scenario(sc))
        stop_time = scenario.simulation.stop_time
        configs = [(label, comps) for label, comps in FREIGHT_LOOPS
                   if all(scenario.components[c].fmu in NATIVE for c in comps)]
        runs: dict[str, list] = {label: [] for label, _ in configs}
        for k in range(repeat + 1):  # alternating, the first round a warm-up
            for label, comps in configs:
                result = run_scenario(sc, [f"{c}.build=native" for c in comps], plot=False)
                if k:
                    runs[label].append(result)
        rows = {}
        for label, rs in runs.items():
            wall = statistics.median(r.wall_time_s for r in rs)
            plant = statistics.median(r.fmu_wall_time_s["plant"] for r in rs)
            ctrl = statistics.median(r.fmu_wall_time_s["controller"] for r in rs)
            rows[label] = {"rtf": stop_time / wall, "wall_s": wall, "plant_s": plant,
                           "controller_s": ctrl, "rest_s": wall - plant - ctrl}
        base = rows[FREIGHT_LOOPS[0][0]]["rtf"]
        print(f"  {sc}:")
        for label, row in rows.items():
            row["ratio"] = row["rtf"] / base
            print(f"    {label:34s} RTF {row['rtf']:6.0f} ({row['ratio']:4.2f}x)   plant "
                  f"{row['plant_s']:6.3f} s  controller {row['controller_s']:6.3f} s  rest "
                  f"{row['rest_s']:6.3f} s")
        out[sc] = rows
    return out


# plant-only runs of Crh3Train and the Emus: (identifier, scenario giving the parameters,
# communication step s, simulated time s, inputs held)
PLANTS = (
    ("Crh3Train", "seed003_crh3_gpc_eco", 1.0, 600.0, {"force": 3e5}),
    ("Emu3", "seed001_emu_pid", 0.2, 120.0, {f"force[{i}]": 6e4 for i in (1, 2, 3)}),
    ("Emu8", "seed001_emu_pid", 0.2, 120.0, {f"force[{i}]": 2e4 for i in range(1, 9)}),
)


def run_plant_fmu(path: Path, params: dict, step: float, stop: float, inputs: dict) -> float:
    """Wall time (s) of ``stop`` simulated seconds of the plant FMU at ``path``."""
    md = read_model_description(str(path))
    unzipdir = extract(str(path))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    types = {v.name: v.type for v in md.modelVariables}
    outs = [v.valueReference for v in md.modelVariables if v.causality == "output"]
    ins = [vr[n] for n in inputs]
    values = list(inputs.values())
    t0 = time.perf_counter()
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzipdir, instanceName="bench",
                    modelIdentifier=md.coSimulation.modelIdentifier)
    fmu.instantiate()
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    for name, value in params.items():
        if name not in vr:
            continue
        {"String": fmu.setString, "Integer": fmu.setInteger,
         "Boolean": fmu.setBoolean}.get(types[name], fmu.setReal)([vr[name]], [value])
    fmu.exitInitializationMode()
    for k in range(round(stop / step)):
        fmu.setReal(ins, values)
        fmu.doStep(k * step, step)
        fmu.getReal(outs)
    fmu.terminate()
    fmu.freeInstance()
    return time.perf_counter() - t0


def plants_only(repeat: int) -> None:
    """Plant-only real-time factors of Crh3Train, Emu3, Emu8: Python FMU against native."""
    specs = catalog()
    build_stale([specs[ident] for ident, *_ in PLANTS])
    for ident, scenario, step, stop, inputs in PLANTS:
        native = build_native(ident, windows=False)
        sc = load_scenario(find_scenario(scenario))
        params = dict(sc.components["plant"].parameters)
        if ident == "Emu8":  # the 8-car train: its own configuration, the line and noise
            params.pop("configuration", None)
        medians = {}
        for label, path in (("Python FMU", specs[ident].path), ("native FMU", native)):
            run_plant_fmu(path, params, step, stop, inputs)  # warm-up (extraction, imports)
            medians[label] = statistics.median(
                run_plant_fmu(path, params, step, stop, inputs) for _ in range(repeat))
        py, nat = medians["Python FMU"], medians["native FMU"]
        print(f"  {ident:14s} {stop:5g} s in {step:g}-s steps: real-time factor Python FMU "
              f"{stop / py:9.0f}, native {stop / nat:9.0f}   native / Python {py / nat:6.1f}x")


def build_all() -> dict:
    """``python -m cosim.cli build --native --fmi all`` in the project folder: wall time (s),
    CPU time of the command and its compilers (s, user + system), the number of FMUs built,
    whether the Windows binaries were among them, and the load averages before and after."""
    from cosim.build.native import WINDOWS_CC

    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    load_before = os.getloadavg()[0]
    t0 = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "cosim.cli", "build", "--native", "--fmi", "all"],
                          cwd=ROOT, capture_output=True, text=True,
                          env=dict(os.environ, PYTHONPATH=str(ROOT)))
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode != 0:
        raise RuntimeError(f"cosim build --native failed:\n{done.stdout}{done.stderr}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return {"wall_s": wall, "cpu_s": cpu, "fmus": done.stdout.count("built "),
            "windows": shutil.which(WINDOWS_CC) is not None, "cpus": os.cpu_count(),
            "load_before": load_before, "load_after": os.getloadavg()[0]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--plants", nargs="+", choices=("freight", "freight_loops", "brake_delay",
                                                  "crh3_emu", "build"),
                    default=["freight", "brake_delay", "crh3_emu", "build"])
    args = ap.parse_args()
    if "build" in args.plants:
        r = build_all()
        print(f"cosim build --native --fmi all: {r['fmus']} FMUs in {r['wall_s']:.1f} s wall, "
              f"{r['cpu_s']:.1f} s CPU (load {r['load_before']:.1f} -> {r['load_after']:.1f} "
              f"on {r['cpus']} cores)")
    if "freight" in args.plants:
        bench_freight(args.repeat)
    if "freight_loops" in args.plants:
        freight_loops(args.repeat)
    if "brake_delay" in args.plants:
        bench_brake_delay(args.repeat)
    if "crh3_emu" in args.plants:
        print(f"\nplant only, Crh3Train / Emu3 / Emu8 (median of {args.repeat}):")
        plants_only(args.repeat)


def bench_brake_delay(repeat: int) -> None:
    t0 = time.perf_counter()
    native = build_native("BrakeDelayTrain", windows=False)
    print(f"\nnative build BrakeDelayTrain (linux64): {time.perf_counter() - t0:.2f} s")
    specs = catalog()
    build_stale([specs["BrakeDelayTrain"]])
    params = plant_parameters()
    rows = {
        "core (Python)": lambda: run_core(params),
        "Python FMU": lambda: run_fmu(specs["BrakeDelayTrain"].path, params),
        "native FMU": lambda: run_fmu(native, params),
    }
    print(f"\nplant only, BrakeDelayTrain, {STOP:g} s in {STEP:g}-s steps "
          f"(median of {repeat}):")
    medians = {}
    for name, fn in rows.items():
        fn()  # warm-up (extraction, imports)
        medians[name] = statistics.median(fn() for _ in range(repeat))
        print(f"  {name:14s} {medians[name] * 1e3:8.2f} ms   real-time factor "
              f"{STOP / medians[name]:10.0f}")
    print(f"  native / Python FMU speed-up: {medians['Python FMU'] / medians['native FMU']:.1f}x")
    print("\nclosed loop, event master (plant FMU wall time and whole-run real-time factor):")
    for sc in [n for n in scenario_files() if n.startswith("seed000_")]:
        res = {}
        for label, over in (("Python", None), ("native", {"plant.fmu": str(native)})):
            run_scenario(sc, overrides=over, plot=False)  # warm-up
            runs = [run_scenario(sc, overrides=over, plot=False) for _ in range(repeat)]
            res[label] = (statistics.median(r.fmu_wall_time_s["plant"] for r in runs),
                          statistics.median(r.wall_time_s for r in runs))
        (pp, pw), (np_, nw) = res["Python"], res["native"]
        print(f"  {sc:24s} plant {pp * 1e3:7.1f} -> {np_ * 1e3:6.2f} ms ({pp / np_:5.1f}x)   "
              f"RTF {STOP / pw:7.0f} -> {STOP / nw:7.0f} ({pw / nw:4.1f}x)")


if __name__ == "__main__":
    main()
