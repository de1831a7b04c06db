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
import json
import os
import shutil
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from cosim.build.python import FMU_DIR, build_stale, resolve  # noqa: E402


def fresh_process_times(names: list[str], count: int = 6) -> dict[str, dict[str, float]]:
    """:func:`instance_times` in a new Python process per FMU, which imports none of the
    FMU's code itself: the first instance pays the imports, as in a fresh host. The FMUs must
    be built (``build_stale``)."""
    import subprocess

    out = {}
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    for name in names:
        code = (f"import sys; sys.path.insert(0, {str(Path(__file__).parent)!r}); "
                f"sys.argv = ['x', '--json', '--count', '{count}', {name!r}]; "
                "import bench_instances; bench_instances.main()")
        done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                              check=True, cwd=ROOT, env=env)
        out.update(json.loads(done.stdout.strip().splitlines()[-1]))
    return out

DEFAULT = ["StopRmpc", "FreightTrain", "Emu3", "FreightPid"]


def instance_times(name: str, count: int = 6) -> dict[str, float]:
    """{first_s, further_ms (median), host_ms (median FMU2Slave construction)} for one FMU."""
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave

    path = str(FMU_DIR / f"{name}.fmu")  # no catalog(): that would import the wrappers
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
    parser.add_argument("--json", action="store_true", help="print the figures as JSON")
    args = parser.parse_args()
    if args.json:
        print(json.dumps({name: instance_times(name, args.count) for name in args.names}))
        return
    build_stale(resolve(args.names))
    print(f"{'FMU':<14} {'first s':>8} {'further ms':>11} {'fmpy object ms':>15}")
    for name, r in fresh_process_times(args.names, args.count).items():
        print(f"{name:<14} {r['first_s']:>8.2f} {r['further_ms']:>11.1f} {r['host_ms']:>15.1f}")


if __name__ == "__main__":
    main()
