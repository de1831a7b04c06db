"""Freeing an instance twice is refused with a message to the host's logger (as the FMI
Reference FMUs' state machine does) instead of freeing its memory twice: the Python FMUs' shim
(where pythonfmu would abort), the native FMI 2 front and the FMI 3 front (where free() of a
freed block would crash). Each case runs in a child process, so a crash fails the test instead
of ending pytest."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from cosim.build.python import build_stale, catalog

CHILD = r"""
import json, sys
from fmpy import extract, read_model_description

path, version = sys.argv[1], sys.argv[2]
md = read_model_description(path)
unzipdir = extract(path)
messages = []
if version == "2":
    from fmpy.fmi2 import FMU2Slave
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzipdir,
                    modelIdentifier=md.coSimulation.modelIdentifier, instanceName="twice")
    fmu.instantiate(loggingOn=False)  # fmpy's default logger prints the messages
    free = fmu.fmi2FreeInstance
else:
    from fmpy.fmi3 import FMU3Slave
    fmu = FMU3Slave(guid=md.guid, unzipDirectory=unzipdir,
                    modelIdentifier=md.coSimulation.modelIdentifier, instanceName="twice")
    fmu.instantiate(loggingOn=False, logMessage=lambda env, status, category, message:
                    messages.append(message.decode()))
    free = fmu.fmi3FreeInstance
component = fmu.component
free(component)
free(component)  # the second time: refused, logged
print(json.dumps(messages))
"""


def _free_twice(path, version: str, logger_messages: bool) -> list[str]:
    """Messages the FMU logged for the second free (FMI 3 through the logMessage callback,
    FMI 2 through fmpy's default logger, which prints them)."""
    done = subprocess.run([sys.executable, "-c", CHILD, str(path), version],
                          capture_output=True, text=True)
    assert done.returncode == 0, f"exit status {done.returncode}: {done.stderr[-2000:]}"
    lines = done.stdout.strip().splitlines()
    return json.loads(lines[-1]) if logger_messages else lines[:-1]


def test_python_fmu_refuses_a_second_free(built_fmus):
    said = _free_twice(built_fmus["StopPid"].path, "2", logger_messages=False)
    assert any("fmi2FreeInstance: instance 'twice' was freed already; call refused" in line
               for line in said), said


def test_python_fmu_fmi3_build_refuses_a_second_free(built_fmus):
    build_stale([catalog()["StopPid"]], fmi_version=3)
    said = _free_twice(catalog()["StopPid"].path_fmi3, "3", logger_messages=True)
    assert said == ["twice: fmi3FreeInstance: the instance was freed already; call refused"]


@pytest.mark.parametrize("version", ["2", "3"])
def test_native_fmu_refuses_a_second_free(version):
    from cosim.build.native import CompilerMissing, build_natives, native_is_stale, native_path

    fmi = int(version)
    if native_is_stale("StopPid", fmi):
        try:
            build_natives("StopPid", (fmi,))
        except CompilerMissing as err:
            pytest.skip(str(err))
    said = _free_twice(native_path("StopPid", fmi), version, logger_messages=version == "3")
    expected = ("twice: fmi3FreeInstance: the instance was freed already; call refused"
                if version == "3" else
                "fmi2FreeInstance: instance 'twice' was freed already; call refused")
    assert any(expected in line for line in said), said
