"""The C shim in front of pythonfmu's linux64 binary (cosim/fmu/pythonfmu_shim.c, installed by
`cosim build`): rejected calls return fmi2Error (pythonfmu alone: fmi2Fatal) and the instance
stays usable; every FMI 2.0 function is exported; the win64 binary is pythonfmu's."""

from __future__ import annotations

import ctypes
import hashlib
import math
import zipfile
from pathlib import Path

import pytest
import pythonfmu
from fmpy import extract, read_model_description

from cosim.build.python import SHIM_SUFFIX, shim_binary
from cosim.interop.compliance import _Host

FMI2_FUNCTIONS = (
    "GetTypesPlatform GetVersion SetDebugLogging Instantiate FreeInstance SetupExperiment "
    "EnterInitializationMode ExitInitializationMode Terminate Reset GetReal GetInteger "
    "GetBoolean GetString SetReal SetInteger SetBoolean SetString GetFMUstate SetFMUstate "
    "FreeFMUstate SerializedFMUstateSize SerializeFMUstate DeSerializeFMUstate "
    "GetDirectionalDerivative EnterEventMode NewDiscreteStates EnterContinuousTimeMode "
    "CompletedIntegratorStep SetTime SetContinuousStates GetDerivatives GetEventIndicators "
    "GetContinuousStates GetNominalsOfContinuousStates SetRealInputDerivatives "
    "GetRealOutputDerivatives DoStep CancelStep GetStatus GetRealStatus GetIntegerStatus "
    "GetBooleanStatus GetStringStatus").split()
FMI2_ERROR, FMI2_FATAL = 3, 4


@pytest.fixture(scope="module")
def stop_pid(built_fmus, tmp_path_factory):
    if shim_binary() is None:
        pytest.skip("the shim cannot be built here (no gcc): FMUs keep pythonfmu's binary")
    path = built_fmus["StopPid"].path
    unzipdir = extract(str(path), unzipdir=str(tmp_path_factory.mktemp("stoppid")))
    return path, unzipdir


def _digest(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def test_binaries_layout(stop_pid):
    path, _ = stop_pid
    shipped = Path(pythonfmu.__file__).parent / "resources" / "binaries"
    with zipfile.ZipFile(path) as z:
        names = set(z.namelist())
        assert {"binaries/linux64/StopPid.so", f"binaries/linux64/StopPid{SHIM_SUFFIX}.so",
                "binaries/win64/StopPid.dll"} <= names
        inner = z.read(f"binaries/linux64/StopPid{SHIM_SUFFIX}.so")
        assert _digest(inner) == _digest(
            (shipped / "linux64" / "libpythonfmu-export.so").read_bytes())
        assert _digest(z.read("binaries/win64/StopPid.dll")) == _digest(
            (shipped / "win64" / "pythonfmu-export.dll").read_bytes())
        assert z.read("binaries/linux64/StopPid.so") != inner


def test_shim_exports_every_fmi2_function(stop_pid):
    _, unzipdir = stop_pid
    lib = ctypes.CDLL(str(Path(unzipdir) / "binaries" / "linux64" / "StopPid.so"))
    missing = [f for f in FMI2_FUNCTIONS if not hasattr(lib, f"fmi2{f}")]
    assert not missing
    lib.fmi2GetTypesPlatform.restype = lib.fmi2GetVersion.restype = ctypes.c_char_p
    assert lib.fmi2GetTypesPlatform() == b"default" and lib.fmi2GetVersion() == b"2.0"


def test_rejections_return_error_and_the_instance_stays_usable(stop_pid):
    path, unzipdir = stop_pid
    host = _Host(path, unzipdir, 10)
    vr = {v.name: v.valueReference for v in read_model_description(str(path)).modelVariables}
    inst = host.instance("shim")
    statuses = [inst.call("doStep", currentCommunicationPoint=0.0,
                          communicationStepSize=host.h)[0]]  # before initialisation
    inst.init()
    statuses.append(inst.call("setReal", [vr["v"]], [math.nan])[0])
    statuses.append(inst.call("doStep", currentCommunicationPoint=0.0,
                              communicationStepSize=-host.h)[0])
    assert statuses == [FMI2_ERROR] * 3
    assert all(s != FMI2_FATAL for s, _ in inst.messages)  # log statuses are mapped too
    assert any("rejected" in m for _, m in inst.messages)
    for k in range(5):  # the instance still works
        inst.set_inputs(host.input_values(k))
        inst.must("doStep", currentCommunicationPoint=k * host.h, communicationStepSize=host.h)
    assert all(math.isfinite(x) for x in inst.read_outputs())
    inst.must("terminate")
    inst.free()


def test_model_exchange_is_refused(stop_pid):
    """pythonfmu would instantiate a co-simulation slave for a model-exchange request."""
    path, unzipdir = stop_pid
    from fmpy.fmi2 import FMU2Model

    md = read_model_description(str(path))
    fmu = FMU2Model(guid=md.guid, unzipDirectory=unzipdir, instanceName="me",
                    modelIdentifier=md.coSimulation.modelIdentifier)
    with pytest.raises(Exception, match="(?i)instantiate"):
        fmu.instantiate()
