"""Wall time and real-time factor of the EMU scenarios (prints figures, asserts nothing).

For each scenario:

* plant only, core: the plant core (no FMI) advanced over the scenario's duration in
  communication steps of the controller sample time, with the per-unit forces recorded in a
  closed-loop run replayed as inputs;
* plant only, FMU: the same through the plant FMU (fmpy ``FMU2Slave``, one
  setReal/doStep/getReal per step);
* closed loop: the whole scenario through the event-driven master (FMUs), summary included.

    python benchmarks/bench_plants.py [--repeat 1] [--scenario seed001_emu_pid ...]

The freight developer adds the freight scenario as a sibling script or a new entry here.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from cosim.fmu.state import to_ticks  # noqa: E402
from cosim.run.scenario import find_scenario, load_scenario  # noqa: E402
from cosim.run.simulate import run_scenario  # noqa: E402
from plants.emu import Emu, emu_config  # noqa: E402
from plants.route import load_route  # noqa: E402

SCENARIOS = ["seed001_emu_pid", "seed004_crh3_pid"]


def _plant_setup(name: str):
    sc = load_scenario(find_scenario(name))
    plant = sc.components["plant"]
    ctl = sc.components["controller"]
    return sc, plant, ctl


def plant_core_run(name: str, forces: np.ndarray, step: float,
                   kernel: bool | None = None) -> float:
    """Wall time of the plant core replaying ``forces``; ``kernel=False``: numpy reference."""
    sc, plant, _ = _plant_setup(name)
    par = plant.parameters
    keys = ("max_step", "disturbance_accel_std", "disturbance_interval", "disturbance_seed")
    over = {k: par[k] for k in keys if k in par}
    emu = Emu(emu_config(par["configuration"], **over), load_route(par["route"]),
              v0=par.get("v0", 0.0), s0=par.get("s0", 0.0), kernel=kernel)
    n = emu.n
    t0 = time.perf_counter()
    h = to_ticks(step)
    for k, row in enumerate(forces):
        emu.advance(k * h, h, {f"force[{i + 1}]": row[i] for i in range(n)})
        emu.outputs()
    return time.perf_counter() - t0


def plant_fmu_run(name: str, forces: np.ndarray, step: float) -> float:
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave

    sc, plant, _ = _plant_setup(name)
    path = str(plant.fmu_path)
    md = read_model_description(path)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    unzip = extract(path)
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzip, modelIdentifier=md.coSimulation
                    .modelIdentifier, instanceName="bench")
    fmu.instantiate()
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    for key, value in plant.parameters.items():
        if isinstance(value, str):
            fmu.setString([vr[key]], [value])
        elif isinstance(value, bool):
            fmu.setBoolean([vr[key]], [value])
        elif isinstance(value, int) and key == "disturbance_seed":
            fmu.setInteger([vr[key]], [value])
        else:
            fmu.setReal([vr[key]], [float(value)])
    fmu.exitInitializationMode()
    n = forces.shape[1]
    in_refs = [vr[f"force[{i + 1}]"] for i in range(n)]
    out_refs = [vr["v"], vr["s"]] + [vr[f"traction_limit[{i + 1}]"] for i in range(n)]
    t0 = time.perf_counter()
    for k, row in enumerate(forces):
        fmu.setReal(in_refs, list(row))
        fmu.doStep(currentCommunicationPoint=k * step, communicationStepSize=step)
        fmu.getReal(out_refs)
    wall = time.perf_counter() - t0
    fmu.terminate()
    fmu.freeInstance()
    return wall


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=1)
    parser.add_argument("--scenario", nargs="*", default=SCENARIOS)
    args = parser.parse_args()
    print(f"{'scenario':<20} {'mode':<18} {'sim s':>8} {'wall s':>8} {'RTF':>8}")
    for name in args.scenario:
        sc, plant, ctl = _plant_setup(name)
        result = None
        walls = []
        for _ in range(args.repeat):
            t0 = time.perf_counter()
            result = run_scenario(find_scenario(name), plot=False)
            walls.append(time.perf_counter() - t0)
        step = float(ctl.sample_time or sc.simulation.base_step)
        n = len([c for c in result.frame.columns if c.startswith("plant.applied_force[")])
        # replay the commanded forces of the closed loop (held over each sample)
        frame = result.frame
        times = np.arange(0.0, sc.simulation.stop_time - 1e-9, step)
        idx = np.searchsorted(frame["time"].to_numpy(), times, side="right") - 1
        forces = np.column_stack([frame[f"plant.applied_force[{i + 1}]"].to_numpy()[idx]
                                  for i in range(n)])
        sim = len(times) * step
        core = statistics.median(plant_core_run(name, forces, step) for _ in range(args.repeat))
        fmu = statistics.median(plant_fmu_run(name, forces, step) for _ in range(args.repeat))
        closed = statistics.median(walls)
        for mode, wall in (("plant core", core), ("plant FMU", fmu),
                           ("closed loop (FMUs)", closed)):
            print(f"{name:<20} {mode:<18} {sim:>8.0f} {wall:>8.2f} {sim / wall:>8.0f}")
        s = result.summary
        print(f"{'':<20} summary: speed error max {s.get('max_abs_speed_error_kmh', 0):.3f} km/h,"
              f" CTCS-3 {s.get('ctcs3_speed_error_ok')}, MSE {s.get('speed_mse_kmh2', 0):.4f}"
              f" km/h^2, IAE {s.get('iae_kmh_s', 0):.1f} km/h s, max |a| "
              f"{s.get('max_abs_accel_mps2', 0):.3f} m/s^2, max coupler "
              f"{s.get('max_coupler_force_kn', 0):.1f} kN, energy {s.get('energy_kwh', 0):.1f} kWh")


if __name__ == "__main__":
    main()
