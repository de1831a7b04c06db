"""Memory a host keeps per FMU instance it creates and frees (prints figures, asserts nothing).

For each FMU, in a fresh Python process: a host's run repeated ``--cycles`` times (load the
binary, ``fmi2Instantiate``, set up, initialise, terminate, ``fmi2FreeInstance``, unload),
after ``--warm`` such runs that pay the imports. The figures are the growth of the process's
resident set (``VmRSS``) per run and the slave classes alive at the end (a Python FMU: one,
``tests/test_instance_cycles.py``). A native FMU's growth is the host's own noise floor.

    python benchmarks/bench_instance_memory.py [--cycles 400] [--warm 20] [FMU ...]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from cosim.build.python import build_stale, catalog  # noqa: E402

DEFAULT = ["StopPid", "BrakeDelayTrain"]

CHILD = r"""
import gc, json, sys
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave

path, cycles, warm = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
md = read_model_description(path)
identifier = md.coSimulation.modelIdentifier
unzipdir = extract(path)


def rss_kb():
    with open("/proc/self/status") as status:
        return next(int(line.split()[1]) for line in status if line.startswith("VmRSS"))


def run():
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzipdir, modelIdentifier=identifier,
                    instanceName="cycle")
    fmu.instantiate()
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    fmu.terminate()
    fmu.freeInstance()


for _ in range(warm):
    run()
gc.collect()
before = rss_kb()
for _ in range(cycles):
    run()
gc.collect()
alive = sum(1 for o in gc.get_objects() if isinstance(o, type) and o.__name__ == identifier)
print(json.dumps({"kb_per_run": (rss_kb() - before) / cycles, "classes_alive": alive}))
"""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("fmus", nargs="*", default=DEFAULT,
                    help="FMU identifiers (built if stale) or .fmu paths")
    ap.add_argument("--cycles", type=int, default=400)
    ap.add_argument("--warm", type=int, default=20)
    a = ap.parse_args()
    build_stale([catalog()[n] for n in a.fmus if not n.endswith('.fmu')])
    print(f"{'FMU':<20} {'KB per run':>10} {'classes alive':>14}   ({a.cycles} runs)")
    for name in a.fmus:
        path = Path(name) if name.endswith(".fmu") else catalog()[name].path
        done = subprocess.run([sys.executable, "-c", CHILD, str(path), str(a.cycles),
                               str(a.warm)], capture_output=True, text=True, check=True)
        got = json.loads(done.stdout.strip().splitlines()[-1])
        print(f"{Path(name).stem:<20} {got['kb_per_run']:>10.2f} {got['classes_alive']:>14}")


if __name__ == "__main__":
    main()
