"""Benchmark of the seed 001 data-driven controllers (prints figures, asserts nothing).

Every table prints the load average: on a shared machine wall times are pessimistic, so CPU
times (this process) are printed beside them.

1. Wall and CPU time per controller event (median and 99th percentile of ``compute``: scaling,
   reference look-up, estimator, law, QP when ISMPC's constraints are active), from a direct
   closed loop of the Emu core (CRH380A, seed001 disturbance) and each controller core over
   the first ``--seconds`` of the Jinan West - Xuzhou East run.
2. Real-time factor of each seed-001 scenario (3600 s simulated) through the event-driven
   master with the FMUs (``--scenarios``; 5 runs of 1-3 min each on this machine), by wall
   time and by the CPU time of the process (plant and controller FMUs run in it), and the
   controller FMU's share of the FMU wall time.

    python benchmarks/bench_datadriven.py [--seconds 600] [--scenarios]
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path[:0] = [str(ROOT)]

from controllers.datadriven.emu_control import EmuGpc, EmuIsmc, EmuIsmpc, EmuMfac  # noqa: E402
from controllers.pid.speed_pid import (  # noqa: E402
    DistributedSpeedPid,
    DistributedSpeedPidParams,
)
from cosim.fmu.state import to_ticks  # noqa: E402
from plants.emu import Emu, emu_config  # noqa: E402
from plants.route import load_reference, load_route  # noqa: E402

CONTROLLERS = {"ISMPC": EmuIsmpc, "ISMC": EmuIsmc, "MFAC": EmuMfac, "GPC": EmuGpc}
SCENARIOS = {"ISMPC": "seed001_emu_ismpc", "ISMC": "seed001_emu_ismc",
             "MFAC": "seed001_emu_mfac", "GPC": "seed001_emu_gpc", "PID": "seed001_emu_pid"}
PID_T = 0.2  # seed001_emu_pid's sample time; the four laws use their own (1 s)


def load_average() -> str:
    return " ".join(f"{x:.2f}" for x in os.getloadavg())


def event_times(controller, seconds: float, T: float) -> tuple[np.ndarray, np.ndarray]:
    """Wall and CPU time (s) of each ``compute`` of ``controller`` (sampled every ``T``) in
    closed loop with the Emu core."""
    emu = Emu(emu_config("crh380a_3unit", disturbance_accel_std=0.05,
                         disturbance_interval=0.2, disturbance_seed=1),
              load_route("jinan_xuzhou_east"))
    wall, cpu = [], []
    for k in range(int(round(seconds / T))):
        meas = emu.outputs()
        t0, c0 = time.perf_counter(), time.process_time()
        out, _ = controller.compute(k * T, meas)
        cpu.append(time.process_time() - c0)
        wall.append(time.perf_counter() - t0)
        emu.advance(to_ticks(k * T), to_ticks(T), out)
    return np.array(wall), np.array(cpu)


def event_table(seconds: float) -> None:
    profile = load_reference("jinan_xuzhou_east_reference")
    print(f"Time per controller event (direct core loop, first {seconds:.0f} s; "
          f"load average {load_average()})")
    print(f"{'controller':<8} {'T s':>5} {'events':>7} {'median ms':>10} {'p99 ms':>8} "
          f"{'CPU med ms':>11} {'QPs':>6}")
    cores = {name: cls(cls.params_class(), profile, 3) for name, cls in CONTROLLERS.items()}
    cores["PID"] = DistributedSpeedPid(DistributedSpeedPidParams(units=3), profile)
    for name, core in cores.items():
        T = core.drive.sample_time if hasattr(core, "drive") else PID_T
        wall, cpu = event_times(core, seconds, T)
        ms = wall * 1e3
        qps = getattr(getattr(core, "law", None), "qp_solves", "-")
        print(f"{name:<8} {T:>5g} {ms.size:>7} {np.median(ms):>10.3f} "
              f"{np.percentile(ms, 99):>8.3f} {np.median(cpu) * 1e3:>11.3f} {qps!s:>6}")


def scenario_table() -> None:
    from cosim.run.scenario import load_scenario
    from cosim.run.simulate import ensure_built, run_scenario

    print("\nWhole seed-001 scenarios through the event-driven master (FMUs)")
    print(f"{'controller':<8} {'sim s':>6} {'wall s':>8} {'x real time':>12} {'CPU s':>7} "
          f"{'x RT by CPU':>12} {'controller FMU s':>17} {'plant FMU s':>12} {'load':>16}")
    for name, scenario in SCENARIOS.items():
        ensure_built(load_scenario(scenario))
        t0, c0 = time.perf_counter(), time.process_time()
        res = run_scenario(scenario, build=False, plot=False)
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        s = res.summary
        fmu = s["fmu_wall_time_s"]
        ctl, plant = fmu.get("controller", float("nan")), fmu.get("plant", float("nan"))
        sim = s["sim_time_s"]
        print(f"{name:<8} {sim:>6.0f} {wall:>8.1f} {sim / wall:>12.1f} {cpu:>7.1f} "
              f"{sim / cpu:>12.1f} {ctl:>17.1f} {plant:>12.1f} {load_average():>16}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=600.0)
    parser.add_argument("--scenarios", action="store_true",
                        help="also run the five seed-001 scenarios (real-time factors)")
    args = parser.parse_args()
    event_table(args.seconds)
    if args.scenarios:
        scenario_table()


if __name__ == "__main__":
    main()
