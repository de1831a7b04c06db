"""Cost of a further FMU instance in one process (prints figures, asserts nothing).

For each FMU: one extraction, then instances created one after the other; the figure is the
median, over the further instances, of ``fmi2Instantiate`` + setupExperiment + enter/exit
initialisation (what the FMU does); fmpy's own ``FMU2Slave`` object (binding the shared
library's functions) is timed separately as the host's share. The first instance pays the
imports (numba, the bundled modules, compiled-kernel cache loads).

    python benchmarks/bench_instances.py [--count 6] [FMU ...]
"""

from __future__ import annotations

import argparse
import shutil
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from cosim.fmu.build import build_stale, resolve  # noqa: E402

DEFAULT = ["StopRmpc", "FreightTrain", "Emu3", "FreightPid"]


def instance_times(name: str, count: int = 6) -> dict[str, float]:
    """{first_s, further_ms (median), host_ms (median FMU2Slave construction)} for one FMU."""
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave

    path = str(resolve([name])[0].path)
    md = read_model_description(path)
    unzipped = extract(path)
    made, fmu_times, host_times = [], [], []
    try:
        for k in range(count):
            t0 = time.perf_counter()
            fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzipped,
                            modelIdentifier=md.coSimulation.modelIdentifier,
                            instanceName=f"instance{k}")
            t1 = time.perf_counter()
            fmu.instantiate()
            fmu.setupExperiment(startTime=0.0)
            fmu.enterInitializationMode()
            fmu.exitInitializationMode()
            t2 = time.perf_counter()
            made.append(fmu)
            host_times.append(t1 - t0)
            fmu_times.append(t2 - t1)
    finally:
        for fmu in made:
            fmu.terminate()
            fmu.freeInstance()
        shutil.rmtree(unzipped, ignore_errors=True)
    return {"first_s": fmu_times[0],
            "further_ms": 1e3 * statistics.median(fmu_times[1:]),
            "host_ms": 1e3 * statistics.median(host_times[1:])}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("names", nargs="*", default=DEFAULT)
    parser.add_argument("--count", type=int, default=6)
    args = parser.parse_args()
    build_stale(resolve(args.names))
    print(f"{'FMU':<14} {'first s':>8} {'further ms':>11} {'fmpy object ms':>15}")
    for name in args.names:
        r = instance_times(name, args.count)
        print(f"{name:<14} {r['first_s']:>8.2f} {r['further_ms']:>11.1f} {r['host_ms']:>15.1f}")


if __name__ == "__main__":
    main()
