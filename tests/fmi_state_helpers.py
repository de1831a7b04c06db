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
