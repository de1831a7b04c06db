"""A Python FMU loaded, instantiated and freed again and again keeps one slave class per
process (FMI 2 and the FMI 3 build, with and without fmi2Reset / fmi3Reset between).

pythonfmu 0.7 executes the FMU's entry file again for every instance and keeps, never
released, the list of bases of each class it finds there. The generated entry file
(``cosim.build.python``) binds the one class of the process on every execution, so one class is
alive after many instances (a class made per execution stayed alive with its declarations,
about 6 KB an instance). Each case runs in a child process: a crash fails the test instead
of ending pytest."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

CYCLES = 40

CHILD = r"""
import gc, json, sys
from fmpy import extract, read_model_description

path, version, cycles = sys.argv[1], sys.argv[2], int(sys.argv[3])
md = read_model_description(path)
identifier = md.coSimulation.modelIdentifier
unzipdir = extract(path)
if version == "2":
    from fmpy.fmi2 import FMU2Slave as Slave
else:
    from fmpy.fmi3 import FMU3Slave as Slave


def cycle(reset):
    fmu = Slave(guid=md.guid, unzipDirectory=unzipdir, modelIdentifier=identifier,
                instanceName="cycles")  # a host's run: load, instantiate, free, unload
    fmu.instantiate()
    if reset:
        fmu.reset()
    fmu.freeInstance()


for i in range(cycles):
    cycle(reset=i % 2 == 1)
gc.collect()
alive = sum(1 for o in gc.get_objects()
            if isinstance(o, type) and o.__name__ == identifier)
print(json.dumps({"alive": alive}))
"""


def _cycles(path, version: str) -> dict:
    done = subprocess.run([sys.executable, "-c", CHILD, str(path), version, str(CYCLES)],
                          capture_output=True, text=True)
    assert done.returncode == 0, f"exit status {done.returncode}: {done.stderr[-2000:]}"
    return json.loads(done.stdout.strip().splitlines()[-1])


@pytest.mark.parametrize("identifier", ["StopPid", "BrakeDelayTrain"])
def test_python_fmu_keeps_one_slave_class_over_many_instances(built_fmus, identifier):
    alive = _cycles(built_fmus[identifier].path, "2")["alive"]
    assert alive == 1, f"{alive} slave classes alive after {CYCLES} instances"


def test_python_fmi3_build_keeps_one_slave_class_over_many_instances(built_fmus_fmi3):
    alive = _cycles(built_fmus_fmi3["StopPid"].path_fmi3, "3")["alive"]
    assert alive == 1, f"{alive} slave classes alive after {CYCLES} instances"
