"""FMU instances kept alive between runs in one process (an ensemble worker's members).

A run through :class:`cosim.run.master.core.Master` given an :class:`InstancePool` takes the
instance of each of its FMUs from the pool where one is kept (same instance name, version of
the FMU file and event mode) and resets it (:meth:`cosim.run.master.unit.Unit.reset`:
fmi2Reset, FMI 2.0.4 sec. 2.1.6, or fmi3Reset, back to the state right after instantiation,
every variable at its start value) instead of checking the archive, parsing its
modelDescription, loading its library and instantiating it again; after a completed run its
instances go back into the pool, after a failure they are freed. Only units that can be reset
(:attr:`cosim.run.master.unit.Unit.reusable`: FMI 2.0, and FMI 3.0 co-simulation and
Scheduled Execution) are kept.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from cosim.run.master.loading import open_fmu
from cosim.run.master.unit import Unit
from cosim.run.scenario import Scenario

# (instance name, FMU file, its modification time, event mode): one kept instance
Key = tuple[str, str, float, bool]


class InstancePool:
    """Instantiated FMUs between runs, and the checked modelDescription of each FMU file."""

    def __init__(self) -> None:
        self._units: dict[Key, Unit] = {}
        self._descriptions: dict[tuple[str, float], tuple[Any, str]] = {}

    @staticmethod
    def key(instance: str, path: Path, event_mode: bool) -> Key:
        """Where the instance ``instance`` of the FMU file ``path`` is kept."""
        return (instance, str(path), path.stat().st_mtime, event_mode)

    def description(self, sc: Scenario, instance: str, path: Path) -> tuple[Any, str]:
        """:func:`cosim.run.master.loading.open_fmu` of ``path`` (its modelDescription and
        its folder), once per file version."""
        at = (str(path), path.stat().st_mtime)
        if at not in self._descriptions:
            self._descriptions[at] = open_fmu(sc, instance, path)
        return self._descriptions[at]

    def take(self, key: Key) -> Unit | None:
        """The kept instance of ``key`` (no longer in the pool), to be reset before use."""
        return self._units.pop(key, None)

    def give(self, key: Key, unit: Unit) -> None:
        """Keep ``unit`` (instantiated, after its run) for the next run; one that cannot be
        reset, or whose place is taken, is freed."""
        if unit.reusable and key not in self._units:
            self._units[key] = unit
        else:
            unit.free()

    def kept(self) -> list[Unit]:
        """The instances kept now."""
        return list(self._units.values())

    def clear(self) -> None:
        """Free every kept instance."""
        units, self._units = list(self._units.values()), {}
        for unit in units:
            unit.free()

    def __len__(self) -> int:
        return len(self._units)
