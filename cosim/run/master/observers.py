"""Observers of a run: what is kept at the output points.

An :class:`Observer` is called at every output point after the values flowed (libcosim's
observers); the :class:`Recorder` keeps the time series. The summary metrics
(:mod:`cosim.run.metrics`) observe the recorded result after the run.
"""

from __future__ import annotations

import ctypes
from typing import Any

import numpy as np

from cosim.fmu.state import to_seconds
from cosim.run.fmi_batch import Batch
from cosim.run.master.errors import SimulationError
from cosim.run.master.unit import Unit

# families recorded as Python objects in list columns (not numbers)
LIST_FAMILIES = ("String", "Binary")
# 64-bit integer types, recorded in integer arrays of their own: float64 holds integers
# exactly only up to 2**53 (FMI 3 Enumerations are read as Int64)
EXACT_TYPES = {"Int64": np.int64, "UInt64": np.uint64}


def exact_dtype(var: Any) -> Any:
    """The integer dtype that records ``var`` exactly (a 64-bit integer by its type, or by its
    function family: an FMI 3 Enumeration is got as Int64); None for a variable that float64
    (or a list column) records exactly."""
    return EXACT_TYPES.get(var.type) or EXACT_TYPES.get(var.family)



def available_memory() -> int | None:
    """Bytes of memory available to a new allocation (Linux MemAvailable), None if unknown."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return None

class Observer:
    """Called at each output point ``ticks`` (after the values flowed) and at the end."""

    def record(self, ticks: int) -> None:
        raise NotImplementedError


class Recorder(Observer):
    """Records named variables at output points (numbers: Real, Integer, Boolean, Enumeration
    values; String and Binary variables in lists): one FMI call per FMU and function family
    per output point, Reals read by the FMU straight into the row of a preallocated array
    (columns in read order, put in the declared order by :meth:`frame`); 64-bit integers
    (:func:`exact_dtype`) into an integer array per group, so that every value is kept
    exactly. An FMU announcing its next event (``next_event_time``) has it read in the same
    call (:attr:`next_event`)."""

    def __init__(self, refs: list[tuple[Unit, str]], n_points: int) -> None:
        self.refs = refs
        self.columns = [f"{u.name}.{n}" for u, n in refs]
        self.rows = 0
        self.strings = {col + 1: (unit, name, []) for col, (unit, name) in enumerate(refs)
                        if unit.vars[name].family in LIST_FAMILIES}
        groups: dict[tuple[str, str, Any], tuple[Unit, str, list[int], list[int], Any]] = {}
        for col, (unit, name) in enumerate(refs):
            var = unit.vars[name]
            dtype = exact_dtype(var)
            group = groups.setdefault((unit.name, var.family, dtype),
                                      (unit, var.family, [], [], dtype))
            group[2].append(var.vr)
            group[3].append(col + 1)
        # storage: time, then each float group's values (+ its next_event_time) in read order;
        # each integer group in an array of its own (its offset: its index in _exact)
        self._groups: list[tuple[Unit, str, list[int], list[int], bool, int]] = []
        self._exact: list[np.ndarray] = []
        self._exact_columns: list[tuple[int, list[int]]] = []  # (array index, columns)
        width = 1
        for unit, family, vrs, cols, dtype in groups.values():
            if dtype is not None:
                self._groups.append((unit, family, vrs, cols, False, len(self._exact)))
                self._exact_columns.append((len(self._exact), cols))
                self._exact.append(np.zeros((n_points, len(vrs)), dtype=dtype))
                continue
            extra = (unit.has_next_event_output and unit.C_TYPES.get(family) is ctypes.c_double
                     and unit.vars["next_event_time"].family == family)
            if extra:
                vrs = [*vrs, unit.vars["next_event_time"].vr]
            self._groups.append((unit, family, vrs, cols, extra, width))
            if family not in LIST_FAMILIES:
                width += len(vrs)
        self._width = width
        self.check_fits(n_points, width + sum(a.shape[1] for a in self._exact))
        self._store = np.full((n_points, width), np.nan)
        self._floats = [g for g, (_, _, dtype) in zip(self._groups, groups)
                        if g[1] not in LIST_FAMILIES and dtype is None]
        self._positions = [p for g in self._floats for p in range(g[5], g[5] + len(g[3]))]
        self._reads: list[tuple[Batch, Any, int, Any]] | None = None
        self.next_event: dict[Unit, float] = {}  # read at the last sampled point


    # the store, the ordered copy the results frame is made from and the pandas table
    COPIES = 3

    def check_fits(self, n_points: int, width: int) -> None:
        """Refuse, before any step, a recording larger than the memory available: it needs
        ``n_points x width x 8`` bytes, :attr:`COPIES` times while the results are written."""
        need = n_points * width * 8
        available = available_memory()
        if available is not None and self.COPIES * need > available:
            raise SimulationError(
                f"the recording needs {need / 2**30:.3g} GiB ({n_points} output points x "
                f"{width} values x 8 bytes; {self.COPIES * need / 2**30:.3g} GiB with the "
                f"results table), more than the {available / 2**30:.3g} GiB of memory "
                "available: shorten [simulation] stop_time, lengthen output_interval or "
                "record fewer [record] variables")

    def bind(self) -> None:
        """Allocate the FMI calls (after the FMUs are instantiated)."""
        self._reads = []
        floats = {id(g) for g in self._floats}
        for group in self._groups:
            unit, family, vrs, cols, extra, offset = group
            batch = unit.batch(family, vrs, False)
            if family in LIST_FAMILIES:
                target: Any = [self.strings[c][2] for c in cols]
            elif id(group) not in floats:
                target = self._exact[offset]  # an integer group: its own array
            elif batch.fast and unit.C_TYPES.get(family) is ctypes.c_double:
                target = offset
            else:
                target = slice(offset, offset + len(vrs))
            self._reads.append((batch, target, offset + len(vrs) - 1 if extra else -1, unit))

    def reads(self) -> list[tuple[Batch, Any, int, Any]]:
        """The FMI reads of one row, bound on first use: per recorded group (batch, target in
        the row: a float column offset, a slice, an integer array or a list of strings, the
        column of its extra value or -1, unit)."""
        if self._reads is None:
            self.bind()
        return self._reads  # type: ignore[return-value]

    @property
    def data(self) -> np.ndarray:
        """The recorded rows, columns as :attr:`columns` (with time first)."""
        out = np.full((len(self._store), len(self.columns) + 1), np.nan)
        out[:, [0, *[c for g in self._floats for c in g[3]]]] = \
            self._store[:, [0, *self._positions]]
        for index, cols in self._exact_columns:  # as floats here; exact in :meth:`frame`
            out[:, cols] = self._exact[index]
        return out

    def grow(self) -> None:
        """Twice the rows (a run with more output points than foreseen)."""
        self._store = np.vstack([self._store, np.full_like(self._store, np.nan)])
        self._exact[:] = [np.vstack([a, np.zeros_like(a)]) for a in self._exact]
        self.bind()  # the integer groups' targets are the new arrays

    def sample(self, ticks: int) -> None:
        """Read the values at ``ticks`` into the next row (:meth:`commit` keeps it)."""
        if self._reads is None:
            self.bind()
        if self.rows == len(self._store):
            self.grow()
        row = self._store[self.rows]
        row[0] = to_seconds(ticks)
        address = row.ctypes.data
        self._pending: list[tuple[list[Any], list[Any]]] = []
        for batch, target, extra, unit in self._reads:  # type: ignore[union-attr]
            if target.__class__ is int:
                batch.get(address + 8 * target)
            else:
                batch.get()
                if target.__class__ is list:
                    self._pending.append((target, batch.values()))
                elif target.__class__ is np.ndarray:
                    target[self.rows] = batch.values()  # C integers or Python ints: exact
                else:
                    row[target] = batch.buf
            if extra >= 0:
                self.next_event[unit] = float(row[extra])

    def commit(self) -> None:
        for lists, values in self._pending:
            for column, value in zip(lists, values):
                column.append(value)
        self.rows += 1

    def record(self, ticks: int) -> None:
        self.sample(ticks)
        self.commit()

    def last_time(self) -> float | None:
        return float(self._store[self.rows - 1, 0]) if self.rows else None

    def frame(self):
        import pandas as pd

        frame = pd.DataFrame(self.data[: self.rows], columns=["time", *self.columns])
        for index, cols in self._exact_columns:  # every committed row read every value
            for j, col in enumerate(cols):
                frame[frame.columns[col]] = self._exact[index][: self.rows, j]
        for col, (unit, name, values) in self.strings.items():
            if unit.vars[name].family == "Binary":  # as scenarios take them: hexadecimal
                values = [bytes(v).hex() for v in values]
            frame[frame.columns[col]] = pd.Series(values[: self.rows], dtype=object)
        return frame
