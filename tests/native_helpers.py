"""Test helpers for the native C FMUs (cosim/fmu/native): a model built and unzipped once,
instances through fmpy with parameters set by their declared type, the messages an instance
logs with logging off, a native controller's law state read and set through its FMU state
image, and the rows by which two model descriptions are compared."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from fmpy import extract, read_model_description
from fmpy.fmi2 import (
    FMU2Slave,
    defaultCallbacks,
    fmi2CallbackFunctions,
    fmi2CallbackLoggerTYPE,
)

Native = tuple[Path, object, str]  # the FMU file, its model description, its unzipped folder


def build_unzipped(identifier: str, tmp_path_factory, native_builds) -> Native:
    """The native FMI 2 FMU ``identifier`` (Linux binary only; the run's build, fixture
    ``native_builds``), its validated model description and the folder it is unzipped to;
    skips where gcc is absent."""
    path = native_builds(identifier)[2]
    md = read_model_description(str(path), validate=True)
    unzipdir = extract(str(path), unzipdir=str(tmp_path_factory.mktemp("unzip")))
    return path, md, unzipdir


def _collecting(messages: list[str]) -> fmi2CallbackFunctions:
    def logger(env, instance, status, category, message):
        messages.append(message.decode())

    callbacks = fmi2CallbackFunctions()
    callbacks.logger = fmi2CallbackLoggerTYPE(logger)
    callbacks.allocateMemory = defaultCallbacks.allocateMemory
    callbacks.freeMemory = defaultCallbacks.freeMemory
    return callbacks


def initialising(native: Native, messages: list[str] | None = None, name: str = "native"
                 ) -> tuple[FMU2Slave, dict[str, int]]:
    """An instance in Initialization Mode (start time 0), logging off; with ``messages`` every
    message it logs is appended there. Returns the instance and the value references."""
    _, md, unzipdir = native
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzipdir, instanceName=name,
                    modelIdentifier=md.coSimulation.modelIdentifier)
    fmu.instantiate(loggingOn=False,
                    callbacks=None if messages is None else _collecting(messages))
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    return fmu, {v.name: v.valueReference for v in md.modelVariables}


def set_by_type(fmu: FMU2Slave, md, values: dict) -> None:
    """Each value through the setter of its variable's declared type."""
    vr = {v.name: v.valueReference for v in md.modelVariables}
    types = {v.name: v.type for v in md.modelVariables}
    for name, value in values.items():
        setter = {"String": fmu.setString, "Integer": fmu.setInteger,
                  "Boolean": fmu.setBoolean}.get(types[name], fmu.setReal)
        setter([vr[name]], [value])


def open_native(native: Native, params: dict | None = None, messages: list[str] | None = None,
                name: str = "native") -> tuple[FMU2Slave, dict[str, int]]:
    """An initialised instance with ``params`` set (by declared type); see
    :func:`initialising`."""
    fmu, vr = initialising(native, messages, name)
    set_by_type(fmu, native[1], params or {})
    fmu.exitInitializationMode()
    return fmu, vr


def law_doubles(fmu: FMU2Slave, size: int) -> np.ndarray:
    """A native controller's law state: the last ``size`` doubles of its FMU state image
    (controller_backend.c)."""
    state = fmu.getFMUstate()
    image = bytes(fmu.serializeFMUstate(state))
    fmu.freeFMUstate(state)
    return np.frombuffer(image[len(image) - 8 * size:], float)


def set_law_doubles(fmu: FMU2Slave, doubles: np.ndarray) -> None:
    """Set a native controller's law state to ``doubles`` (the end of its FMU state image)."""
    state = fmu.getFMUstate()
    image = bytes(fmu.serializeFMUstate(state))
    fmu.freeFMUstate(state)
    image = image[:len(image) - 8 * doubles.size] + np.asarray(doubles, float).tobytes()
    restored = fmu.deSerializeFMUstate(image)
    fmu.setFMUstate(restored)
    fmu.freeFMUstate(restored)


def variable_rows(md) -> list[tuple]:
    """What two builds of one model must agree on, per variable: name, value reference,
    causality, variability, type, unit, range, start and description."""
    return [(v.name, v.valueReference, v.causality, v.variability, v.type, v.unit, v.min,
             v.max, v.start, v.description) for v in md.modelVariables]
