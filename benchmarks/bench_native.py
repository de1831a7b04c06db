"""Real-time factors of the native C plant FMU against the Python FMU and the Python core,
in one run (prints figures, asserts nothing).

Native plants so far: BrakeDelayTrain (seed 000). For it:

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
