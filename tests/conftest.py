"""Shared fixtures: FMUs are built once per session (only those missing or out of date)."""

from __future__ import annotations

import pytest

from cosim.build import build_stale, catalog


@pytest.fixture(scope="session")
def built_fmus() -> dict:
    """Every catalog FMU, built and up to date: identifier -> FmuSpec (``.path``)."""
    build_stale()
    return catalog()


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
