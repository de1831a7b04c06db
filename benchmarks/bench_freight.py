"""Wall time and real-time factor of the freight scenario (prints figures, asserts nothing).

Target: the 22.8 min run with plant sub-step 0.01 s, closed loop, under 60 s wall.

* closed loop, master: ``seed002_freight_pid`` through the event-driven master (FMUs, summary);
* plant only, core: :class:`plants.freight.FreightTrain` (no FMI) replaying the force demand and
  pipe reduction recorded in that run, one advance per 0.2 s;
* plant only, FMU: the same through the plant FMU (fmpy ``FMU2Slave``, setReal/doStep/getReal);
* closed loop, cores: plant and :class:`controllers.pid.freight_pid.FreightPid` in a Python loop.

    python benchmarks/bench_freight.py [--repeat 1]
"""

from __future__ import annotations

import argparse
import shutil
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from controllers.pid.freight_pid import FreightPid, FreightPidParams  # noqa: E402
from cosim.build.python import resolve  # noqa: E402
from cosim.fmu.state import to_ticks  # noqa: E402
from cosim.run.scenario import find_scenario  # noqa: E402
from cosim.run.simulate import run_scenario  # noqa: E402
from plants.freight import FreightParams, FreightTrain  # noqa: E402
from plants.route import load_route  # noqa: E402

SCENARIO = "seed002_freight_pid"
STEP = 0.2  # s, controller sample time = communication step


def plant_core(inputs: np.ndarray, kernel: bool | None = None) -> float:
    """Wall time of the plant core replaying ``inputs``; ``kernel=False``: numpy reference."""
    train = FreightTrain(FreightParams(), load_route("freight_20km"), kernel=kernel)
    h = to_ticks(STEP)
    t0 = time.perf_counter()
    for k, (force, reduction) in enumerate(inputs):
        train.advance(k * h, h, {"force_demand": force, "pipe_reduction": reduction})
        train.outputs()
    return time.perf_counter() - t0


def plant_fmu(inputs: np.ndarray) -> float:
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave

    path = str(resolve(["FreightTrain"])[0].path)
    md = read_model_description(path)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    unzipped = extract(path)
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzipped,
                    modelIdentifier=md.coSimulation.modelIdentifier, instanceName="plant")
    try:
        fmu.instantiate()
        fmu.setupExperiment(startTime=0.0)
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        ins = [vr["force_demand"], vr["pipe_reduction"]]
        outs = [vr["v"], vr["s"]]
        t0 = time.perf_counter()
        for k, (force, reduction) in enumerate(inputs):
            fmu.setReal(ins, [float(force), float(reduction)])
            fmu.doStep(currentCommunicationPoint=k * STEP, communicationStepSize=STEP)
            fmu.getReal(outs)
        wall = time.perf_counter() - t0
        fmu.terminate()
    finally:
        fmu.freeInstance()
        shutil.rmtree(unzipped, ignore_errors=True)
    return wall


def closed_loop_cores(stop_time: float) -> float:
    route = load_route("freight_20km")
    train = FreightTrain(FreightParams(), route)
    pid = FreightPid(FreightPidParams(), route.reference, route)
    h = to_ticks(STEP)
    t0 = time.perf_counter()
    for k in range(int(round(stop_time / STEP))):
        out = train.outputs()
        cmd, _ = pid.compute(k * STEP, {"v": out["v"], "s": out["s"]})
        train.advance(k * h, h, cmd)
    return time.perf_counter() - t0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=1)
    args = parser.parse_args()
    walls: dict[str, list[float]] = {}
    result = None
    for _ in range(args.repeat):
        t0 = time.perf_counter()
        result = run_scenario(find_scenario(SCENARIO), plot=False)
        walls.setdefault("closed loop, master (FMUs)", []).append(time.perf_counter() - t0)
    frame = result.frame
    sim_time = float(result.sim_time_s)
    inputs = frame[["controller.force_demand", "controller.pipe_reduction"]].to_numpy()
    inputs = inputs[: int(round(sim_time / STEP))]
    for _ in range(args.repeat):
        walls.setdefault("plant only, core", []).append(plant_core(inputs))
        walls.setdefault("plant only, core (numpy)", []).append(plant_core(inputs, False))
        walls.setdefault("plant only, FMU", []).append(plant_fmu(inputs))
        walls.setdefault("closed loop, cores", []).append(closed_loop_cores(sim_time))
    substeps = sim_time / FreightParams().max_step
    print(f"{SCENARIO}: {sim_time:.0f} s simulated, {substeps:.0f} plant sub-steps of 0.01 s")
    for name, values in walls.items():
        wall = statistics.median(values)
        print(f"  {name:28s} wall {wall:7.2f} s   real-time factor {sim_time / wall:7.1f}"
              f"   {wall / substeps * 1e6:6.1f} us per sub-step")
    s = result.summary
    keys = ("speed_mse_kmh2", "iae_kmh_s", "max_abs_speed_error_kmh", "max_abs_accel_mps2",
            "ctcs3_speed_error_ok", "max_coupler_force_kn", "energy_kwh", "stop_error_m",
            "arrival_time_error_s")
    print("  tracking: " + ", ".join(f"{k} = {s.get(k)}" for k in keys))


if __name__ == "__main__":
    main()
