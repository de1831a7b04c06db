"""One FMI get or set of a fixed list of variables, as cheap as an FMI call gets from Python.

A :class:`Batch` is built once per (FMU instance, function family, value references): the
value-reference array and the value buffer are allocated once and the FMU's C function
(``fmi2GetReal``, ``fmi3GetFloat64`` ...; FMI 2.0.4 sec. 2.1.7, FMI 3.0 sec. 2.2.6.2) is called
directly through ctypes with them, so a call costs the FMU's own work plus ~1 us (fmpy's
``getReal`` allocates both arrays and goes through a logging wrapper on every call: ~4 us
more). The buffer can also be caller memory (a
row of the recorder's array), so recorded values are never copied through Python lists.

A non-OK status (above Warning) goes to ``on_error(call, status)``, which raises the
master's error naming the instance, the call and the time. Strings (and Binary, and FMI 3 array
elements), and FMUs loaded by an fmpy without the ``dll``/``component`` attributes, go through
the unit's ``read``/``write``.
"""

from __future__ import annotations

import ctypes
from collections.abc import Callable
from time import perf_counter
from typing import Any

_WARNING = 1  # fmi2Warning, fmi3Warning


class Batch:
    """Get<family> (``get``) or Set<family> (``set``) of ``vrs`` on ``unit`` (a
    :class:`cosim.run.master.unit.Unit` after instantiation: ``raw_slave()``, ``read``,
    ``write``, ``wall_time``, and its ``C_TYPES``, ``C_PREFIX``, ``C_COUNTS``)."""

    def __init__(self, unit: Any, family: str, vrs: list[int], setter: bool,
                 on_error: Callable[[str, int], None], buffer: Any = None) -> None:
        self.unit, self.family, self.vrs, self.n = unit, family, list(vrs), len(vrs)
        self.call = f"{'set' if setter else 'get'}{family}"
        self.on_error = on_error
        raw = unit.raw_slave()
        ctype = unit.C_TYPES.get(family)
        self.fast = ctype is not None and hasattr(raw, "dll") and hasattr(raw, "component")
        self.ctype = ctype if self.fast else None
        if not self.fast:
            self._setter = setter
            self.buf: Any = buffer if buffer is not None else [None] * self.n
            return
        # a private function object
        fn = raw.dll[f"{unit.C_PREFIX}{'Set' if setter else 'Get'}{family}"]
        self._counts = unit.C_COUNTS  # FMI 3: (..., values, nValues)
        fn.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_size_t, ctypes.c_void_p,
                       *([ctypes.c_size_t] if self._counts else [])]
        fn.restype = ctypes.c_int
        self._fn, self._component = fn, raw.component
        self._vr = (ctypes.c_uint * self.n)(*self.vrs)
        self.buf = buffer if buffer is not None else (ctype * self.n)()

    def get(self, into: int | None = None) -> None:
        """Read into :attr:`buf`, or into the memory at address ``into``."""
        t0 = perf_counter()
        if self.fast:
            target = self.buf if into is None else into
            status = (self._fn(self._component, self._vr, self.n, target, self.n)
                      if self._counts else self._fn(self._component, self._vr, self.n, target))
            self.unit.wall_time += perf_counter() - t0
            if status > _WARNING:
                self.on_error(self.call, status)
        else:
            values = self.unit.read(self.family, self.vrs)  # timed by the unit
            self.buf[:] = values

    def set(self) -> None:
        """Write :attr:`buf`."""
        t0 = perf_counter()
        if self.fast:
            status = (self._fn(self._component, self._vr, self.n, self.buf, self.n)
                      if self._counts else self._fn(self._component, self._vr, self.n, self.buf))
            self.unit.wall_time += perf_counter() - t0
            if status > _WARNING:
                self.on_error(self.call, status)
        else:
            self.unit.write(self.family, self.vrs, list(self.buf))  # timed by the unit

    def values(self) -> list[Any]:
        return self.buf[:]
