"""Real-time factors of the native C plant FMU against the Python FMU and the Python core,
in one run (prints figures, asserts nothing).

Plant only, for every native plant model (BrakeDelayTrain, Crh3Train, Emu3, Emu8): the Python
FMU and the native FMU stepped over the same simulated time with a fixed input, in the step of
the plant's shipped scenarios, through fmpy ``FMU2Slave`` (one setReal/doStep/getReal of every
output per step); their real-time factors and the ratio, in the same run.

For BrakeDelayTrain (seed 000) also:

* plant only: the seed-000 plant (scenario parameters of seed000_stop_pid) stepped over 60 s
  in 0.2-s communication steps with a fixed braking command, through the plant core (no FMI),
  the Python FMU and the native FMU (fmpy ``FMU2Slave``, one setReal/doStep/getReal per step);
* closed loop: every shipped seed-000 scenario through the event-driven master with the Python
  plant FMU and with the native one (the controllers are the Python FMUs in both).

The bare C kernel (benchmarks/c_kernel) is the freight kernel; the freight
plant has no native FMU yet, so that comparison is not made here.

    python benchmarks/bench_native.py [--repeat 3]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from fmpy import extract, read_model_description  # noqa: E402
from fmpy.fmi2 import FMU2Slave  # noqa: E402

from cosim.fmu.build import build_stale, catalog  # noqa: E402
from cosim.fmu.native_build import build_native  # noqa: E402
from cosim.fmu.state import to_ticks  # noqa: E402
from cosim.run.master import run_scenario  # noqa: E402
from cosim.run.scenario import load_scenario  # noqa: E402
from plants.brake_delay import BrakeDelayTrain  # noqa: E402

STOP, STEP, COMMAND = 60.0, 0.2, 40.0


def plant_parameters() -> dict:
    sc = load_scenario(ROOT / "scenarios" / "seed000_stop_pid.toml")
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


# plant-only runs of the other native plants: (identifier, scenario giving the parameters,
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
    """Plant-only real-time factors of the other native plants, Python FMU against native."""
    specs = catalog()
    build_stale([specs[ident] for ident, *_ in PLANTS])
    for ident, scenario, step, stop, inputs in PLANTS:
        native = build_native(ident, windows=False)
        sc = load_scenario(ROOT / "scenarios" / f"{scenario}.toml")
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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    t0 = time.perf_counter()
    native = build_native("BrakeDelayTrain", windows=False)
    print(f"native build (linux64): {time.perf_counter() - t0:.2f} s")
    specs = catalog()
    build_stale([specs["BrakeDelayTrain"]])
    params = plant_parameters()
    rows = {
        "core (Python)": lambda: run_core(params),
        "Python FMU": lambda: run_fmu(specs["BrakeDelayTrain"].path, params),
        "native FMU": lambda: run_fmu(native, params),
    }
    print(f"\nplant only, BrakeDelayTrain, {STOP:g} s in {STEP:g}-s steps "
          f"(median of {args.repeat}):")
    medians = {}
    for name, fn in rows.items():
        fn()  # warm-up (extraction, imports)
        medians[name] = statistics.median(fn() for _ in range(args.repeat))
        print(f"  {name:14s} {medians[name] * 1e3:8.2f} ms   real-time factor "
              f"{STOP / medians[name]:10.0f}")
    print(f"  native / Python FMU speed-up: {medians['Python FMU'] / medians['native FMU']:.1f}x")
    print(f"\nplant only, other native plants (median of {args.repeat}):")
    plants_only(args.repeat)
    print("\nclosed loop, event master (plant FMU wall time and whole-run real-time factor):")
    for sc in sorted(p.stem for p in (ROOT / "scenarios").glob("seed000_*.toml")):
        res = {}
        for label, over in (("Python", None), ("native", {"plant.fmu": str(native)})):
            run_scenario(sc, overrides=over, plot=False)  # warm-up
            runs = [run_scenario(sc, overrides=over, plot=False) for _ in range(args.repeat)]
            res[label] = (statistics.median(r.fmu_wall_time_s["plant"] for r in runs),
                          statistics.median(r.wall_time_s for r in runs))
        (pp, pw), (np_, nw) = res["Python"], res["native"]
        print(f"  {sc:24s} plant {pp * 1e3:7.1f} -> {np_ * 1e3:6.2f} ms ({pp / np_:5.1f}x)   "
              f"RTF {STOP / pw:7.0f} -> {STOP / nw:7.0f} ({pw / nw:4.1f}x)")


if __name__ == "__main__":
    main()
