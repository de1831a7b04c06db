"""One FMI get or set of a fixed list of variables, as cheap as an FMI call gets from Python.

A :class:`Batch` is built once per (FMU instance, function family, value references): the
value-reference array and the value buffer are allocated once and the FMU's C function
(``fmi2GetReal`` ...; FMI 2.0.4 sec. 2.1.7) is called directly through ctypes with them, so a
call costs the FMU's own work plus ~1 us (fmpy's ``getReal`` allocates both arrays and goes
through a logging wrapper on every call: ~4 us more). The buffer can also be caller memory (a
row of the recorder's array), so recorded values are never copied through Python lists.

A non-OK status (above fmi2Warning) goes to ``on_error(call, status)``, which raises the
master's error naming the instance, the call and the time. Strings, and FMUs loaded by an fmpy
without the ``dll``/``component`` attributes, go through fmpy's ``get<Type>``/``set<Type>``.
"""

from __future__ import annotations

import ctypes
from collections.abc import Callable
from time import perf_counter
from typing import Any

C_TYPES = {"Real": ctypes.c_double, "Integer": ctypes.c_int, "Boolean": ctypes.c_int}
_FMI2_WARNING = 1


class Batch:
    """fmi2Get<family> (``get``) or fmi2Set<family> (``set``) of ``vrs`` on ``unit`` (an
    :class:`cosim.run.master.FmuUnit` after instantiation: ``slave``, ``wall_time``)."""

    def __init__(self, unit: Any, family: str, vrs: list[int], setter: bool,
                 on_error: Callable[[str, int], None], buffer: Any = None) -> None:
        self.unit, self.family, self.vrs, self.n = unit, family, list(vrs), len(vrs)
        self.call = f"{'set' if setter else 'get'}{family}"
        self.on_error = on_error
        raw = unit.slave._slave if hasattr(unit.slave, "_slave") else unit.slave
        ctype = C_TYPES.get(family)
        self.fast = ctype is not None and hasattr(raw, "dll") and hasattr(raw, "component")
        if not self.fast:
            self._fmpy = getattr(unit.slave, self.call)
            self.buf: Any = buffer if buffer is not None else [None] * self.n
            return
        fn = raw.dll[f"fmi2{'Set' if setter else 'Get'}{family}"]  # a private function object
        fn.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_size_t, ctypes.c_void_p]
        fn.restype = ctypes.c_int
        self._fn, self._component = fn, raw.component
        self._vr = (ctypes.c_uint * self.n)(*self.vrs)
        self.buf = buffer if buffer is not None else (ctype * self.n)()

    def get(self, into: int | None = None) -> None:
        """Read into :attr:`buf`, or into the memory at address ``into``."""
        t0 = perf_counter()
        if self.fast:
            status = self._fn(self._component, self._vr, self.n,
                              self.buf if into is None else into)
            self.unit.wall_time += perf_counter() - t0
            if status > _FMI2_WARNING:
                self.on_error(self.call, status)
        else:
            values = self._fmpy(self.vrs)
            self.unit.wall_time += perf_counter() - t0
            self.buf[:] = [v.decode("utf-8") if isinstance(v, bytes) else v for v in values]

    def set(self) -> None:
        """Write :attr:`buf`."""
        t0 = perf_counter()
        if self.fast:
            status = self._fn(self._component, self._vr, self.n, self.buf)
            self.unit.wall_time += perf_counter() - t0
            if status > _FMI2_WARNING:
                self.on_error(self.call, status)
        else:
            self._fmpy(self.vrs, list(self.buf))
            self.unit.wall_time += perf_counter() - t0

    def values(self) -> list[Any]:
        return self.buf[:]
