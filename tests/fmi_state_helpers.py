"""Test helper: FMU state save/restore through FMI (serialize, continue, restore, rerun)."""

from __future__ import annotations


def rerun_after_restore(instances: list, step, k_save: int, k_end: int) -> tuple[list, list]:
    """Run ``step(k)`` for k < ``k_save``, serialize every instance's FMU state (``.fmu``),
    run on to ``k_end``, restore the states from the bytes and run the same steps again.
    Returns the two lists of step results, which must be equal."""
    for k in range(k_save):
        step(k)
    blobs = [inst.fmu.serializeFMUstate(inst.fmu.getFMUstate()) for inst in instances]
    first = [step(k) for k in range(k_save, k_end)]
    for inst, blob in zip(instances, blobs, strict=True):
        inst.fmu.setFMUstate(inst.fmu.deSerializeFMUstate(blob))
    second = [step(k) for k in range(k_save, k_end)]
    return first, second


def assert_replays_from_state(fmu, rest) -> list:
    """Snapshot ``fmu``'s FMU state (``getFMUstate`` and its serialized bytes), run ``rest()``
    (the rows of the rest of a run), then restore the state and rerun, and restore from the
    bytes and rerun: the same rows each time. Frees both states; returns the rows."""
    state = fmu.getFMUstate()
    blob = fmu.serializeFMUstate(state)
    first = rest()
    fmu.setFMUstate(state)
    assert rest() == first
    restored = fmu.deSerializeFMUstate(blob)
    fmu.setFMUstate(restored)
    assert rest() == first
    fmu.freeFMUstate(state)
    fmu.freeFMUstate(restored)
    return first


class FmuInstance:
    """An initialised fmpy instance of an FMU file with parameters set by type
    (``strings``, ``reals``, ``ints``); ``get``/``set`` read and write Reals by name."""

    def __init__(self, path: str, name: str, strings: dict | None = None,
                 reals: dict | None = None, ints: dict | None = None) -> None:
        from fmpy import extract, read_model_description
        from fmpy.fmi2 import FMU2Slave

        md = read_model_description(path)
        self.vr = {v.name: v.valueReference for v in md.modelVariables}
        self.fmu = FMU2Slave(guid=md.guid, unzipDirectory=extract(path), instanceName=name,
                             modelIdentifier=md.coSimulation.modelIdentifier)
        self.fmu.instantiate()
        self.fmu.setupExperiment(startTime=0.0)
        self.fmu.enterInitializationMode()
        for values, setter in ((strings, self.fmu.setString), (reals, self.fmu.setReal),
                               (ints, self.fmu.setInteger)):
            for k, v in (values or {}).items():
                setter([self.vr[k]], [v])
        self.fmu.exitInitializationMode()

    def get(self, names: list[str]) -> list[float]:
        return self.fmu.getReal([self.vr[n] for n in names])

    def set(self, names: list[str], values: list[float]) -> None:
        self.fmu.setReal([self.vr[n] for n in names], values)
