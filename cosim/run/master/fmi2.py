"""The FMI 2.0 co-simulation unit on fmpy's ``FMU2Slave`` (FMI 2.0.4 sec. 4)."""

from __future__ import annotations

import contextlib
import ctypes
import itertools
import weakref
from collections.abc import Callable
from pathlib import Path
from time import perf_counter
from typing import Any

from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import (
    FMU2Slave,
    calloc,
    fmi2CallbackAllocateMemoryTYPE,
    fmi2CallbackFreeMemoryTYPE,
    fmi2CallbackFunctions,
    fmi2CallbackLoggerTYPE,
    free,
    printLogMessage,
)

from cosim.fmu.state import to_seconds, to_ticks
from cosim.run.fmi_types import FUNCTIONS, enumeration_items
from cosim.run.master.errors import FmuCallError, FmuTerminated, SimulationError
from cosim.run.master.unit import MAX_HALVINGS, Unit, Variable

_FMI2_WARNING, _FMI2_DISCARD = 1, 2
_FMI2_LAST_SUCCESSFUL_TIME, _FMI2_TERMINATED = 2, 3


class CheckedSlave:
    """An fmpy slave whose FMI calls (doStep aside: the unit's ``_do_step`` handles it) raise
    :class:`FmuCallError` naming the instance, the call, the time and what the FMU logged,
    instead of fmpy's bare ``FMICallException``; a failure anywhere keeps the partial results.
    Each wrapped method is built once, on first use, and then found as a plain attribute."""

    def __init__(self, slave: Any, unit: Unit) -> None:
        self._slave, self._unit = slave, unit

    def __getattr__(self, name: str) -> Any:
        attr = getattr(self._slave, name)
        if name == "doStep" or not callable(attr):
            return attr
        unit = self._unit

        def call(*args: Any, **kwargs: Any) -> Any:
            try:
                return attr(*args, **kwargs)
            except Exception as err:
                raise FmuCallError(unit.call_error_text(name, err),
                                   getattr(err, "status", None)) from err

        setattr(self, name, call)
        return call


# The FMI 2 logger is variadic (a printf format and its arguments, FMI 2.0.4 sec. 2.1.5),
# which ctypes cannot receive: fmpy's native proxy (fmpy.logging.addLoggerProxy) formats the
# message with vsnprintf and calls the one Python logger it holds (a process-wide pointer).
# That logger is this module's dispatcher, for every FMU; it finds the FMU's listener by the
# componentEnvironment its callbacks carry (a number, :data:`_LISTENERS`), and hands a
# message of an FMU instantiated by another host in this process (fmpy's own callbacks) to
# fmpy's printLogMessage, as fmpy would.
_LISTENERS: dict[int, Callable[[int, str], None]] = {}
_KEYS = itertools.count(1)


def _dispatch(env: int | None, instance: bytes, status: int, category: bytes,
              message: bytes) -> None:
    listener = _LISTENERS.get(env or 0)
    if listener is None:
        printLogMessage(env, instance, status, category, message)
    else:
        listener(int(status), message.decode("utf-8", "replace") if message else "")


_DISPATCH = fmi2CallbackLoggerTYPE(_dispatch)


def logging_callbacks(on_message: Callable[[int, str], None]) -> fmi2CallbackFunctions:
    """fmpy FMI 2 callbacks that hand every log message (status, text formatted with its
    printf arguments) to ``on_message``. The caller must keep the returned object referenced
    while the FMU instance lives; ``on_message`` is dropped with it."""
    key = next(_KEYS)
    _LISTENERS[key] = on_message
    callbacks = fmi2CallbackFunctions()
    callbacks.logger = _DISPATCH
    callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
    callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
    callbacks.componentEnvironment = key
    with contextlib.suppress(Exception):  # no proxy for this platform: messages unformatted
        from fmpy.logging import addLoggerProxy

        addLoggerProxy(ctypes.byref(callbacks))  # the proxy's logger is _DISPATCH again
    weakref.finalize(callbacks, _LISTENERS.pop, key, None)
    return callbacks


class Fmi2Unit(Unit):
    """An FMI 2.0 co-simulation FMU instance."""

    fmi_version = "2.0"
    C_TYPES = {"Real": ctypes.c_double, "Integer": ctypes.c_int, "Boolean": ctypes.c_int}
    C_PREFIX = "fmi2"

    def __init__(self, name: str, path: Path, unzipdir: str, md: Any) -> None:
        super().__init__(name, path, unzipdir, md)
        self.slave = CheckedSlave(FMU2Slave(guid=md.guid, unzipDirectory=unzipdir,
                                            modelIdentifier=md.coSimulation.modelIdentifier,
                                            instanceName=name), self)
        slave = self.slave
        self._getters: dict[str, Callable[[list[int]], list[Any]]] = {
            "Real": slave.getReal, "Integer": slave.getInteger, "Boolean": slave.getBoolean,
            "String": self._read_strings}
        self._setters: dict[str, Callable[[list[int], list[Any]], None]] = {
            "Real": slave.setReal, "Integer": slave.setInteger, "Boolean": slave.setBoolean,
            "String": slave.setString}
        # kept referenced while the FMU lives
        self._callbacks = logging_callbacks(lambda status, text: self.messages.append(text))

    def variables(self, md: Any) -> dict[str, Variable]:
        return {v.name: Variable(v.valueReference, v.type, v.causality, enumeration_items(v),
                                 FUNCTIONS[v.type]) for v in md.modelVariables}

    def raw_slave(self) -> Any:
        return self.slave._slave

    def instantiate(self, event_mode: bool = False) -> None:
        self.slave.instantiate(callbacks=self._callbacks, loggingOn=True)

    def enter_initialization(self, start: float, stop: float) -> None:
        self.slave.setupExperiment(startTime=start, stopTime=stop)
        self.slave.enterInitializationMode()

    def exit_initialization(self) -> None:
        self.slave.exitInitializationMode()

    def terminate(self) -> None:
        self.slave.terminate()

    def free(self) -> None:
        self.slave.freeInstance()

    reusable = True

    def reset(self) -> None:
        """fmi2Reset (FMI 2.0.4 sec. 2.1.6): the state after fmi2Instantiate, every variable
        at its start value; what the FMU logs while resetting is kept, as at instantiation."""
        self.reset_run_state()
        self.slave.reset()

    def get_state(self) -> Any:
        return self.slave.getFMUstate()

    def set_state(self, state: Any) -> None:
        self.slave.setFMUstate(state)

    # -- values ------------------------------------------------------------------------------
    def read(self, family: str, vrs: list[int]) -> list[Any]:
        """One fmi2Get<family> (``Real``, ``Integer``, ``Boolean``, ``String``) of ``vrs``;
        Strings decoded."""
        t0 = perf_counter()
        values = self._getters[family](vrs)
        self.wall_time += perf_counter() - t0
        return values

    def write(self, family: str, vrs: list[int], values: list[Any]) -> None:
        t0 = perf_counter()
        self._setters[family](vrs, values)
        self.wall_time += perf_counter() - t0

    def _read_strings(self, vrs: list[int]) -> list[str]:
        return [v.decode("utf-8") if isinstance(v, bytes) else v
                for v in self.slave.getString(vrs)]

    # -- stepping ----------------------------------------------------------------------------
    def _do_step(self, t: int, h: int, first_status: int | None = None) -> int:
        """One communication step; fmi2Discard ends the run if the FMU terminated, else the
        step is retried in smaller pieces (``MAX_HALVINGS``) if the FMU handles variable steps.
        Inputs keep the values set at ``t`` over every piece. ``first_status``: the first
        fmi2DoStep(t, h) was made (and counted) already and returned this status."""
        end, piece, halvings = t + h, h, 0
        while t < end:
            piece = min(piece, end - t)
            if first_status is None:
                status = self._c_do_step(to_seconds(t), to_seconds(piece))
                self.do_steps += 1
            else:
                status, first_status = first_status, None
            if status <= _FMI2_WARNING:
                t += piece
                continue
            if status != _FMI2_DISCARD:
                raise FMICallException(function="fmi2DoStep", status=status)
            if self._status("getBooleanStatus", _FMI2_TERMINATED, False):
                last = self._status("getRealStatus", _FMI2_LAST_SUCCESSFUL_TIME, None)
                raise FmuTerminated(self, to_ticks(last) if last is not None else t)
            if not self.variable_step:
                raise SimulationError(
                    f"{self.name}: doStep at t={to_seconds(t)} s, h={to_seconds(piece)} s "
                    "returned fmi2Discard (step refused) and the FMU cannot handle variable "
                    "communication step sizes (canHandleVariableCommunicationStepSize=false), "
                    f"so the step cannot be retried in smaller pieces: give [fmus.{self.name}] "
                    f"a smaller max_step, or a smaller base_step; FMU says: "
                    f"{self.last_messages()}")
            last = self._status("getRealStatus", _FMI2_LAST_SUCCESSFUL_TIME, None)
            if last is not None and t < to_ticks(last) < t + piece:
                t = to_ticks(last)
            halvings += 1
            if halvings > MAX_HALVINGS or piece < 2:
                raise SimulationError(
                    f"{self.name}: doStep at t={to_seconds(t)} s returned fmi2Discard for "
                    f"steps down to h={to_seconds(piece)} s ({MAX_HALVINGS} halvings of the "
                    f"communication step): giving up; FMU says: {self.last_messages()}")
            piece //= 2
        return end

    def _c_do_step(self, t: float, h: float) -> int:
        """fmi2DoStep(t, h, noSetFMUStatePriorToCurrentPoint = true): its status. The C
        function directly (the first call looks it up), or fmpy's doStep."""
        raw = self.slave._slave
        if hasattr(raw, "dll") and hasattr(raw, "component"):
            fn = raw.dll["fmi2DoStep"]  # a private function object: our argtypes
            fn.argtypes = [ctypes.c_void_p, ctypes.c_double, ctypes.c_double, ctypes.c_int]
            fn.restype = ctypes.c_int
            component = raw.component

            def do_step(t: float, h: float) -> int:
                return fn(component, t, h, 1)
        else:
            def do_step(t: float, h: float) -> int:
                try:
                    raw.doStep(currentCommunicationPoint=t, communicationStepSize=h)
                except FMICallException as err:
                    return int(err.status)
                return 0

        self._c_do_step = do_step  # type: ignore[method-assign]
        return do_step(t, h)

    def _status(self, method: str, kind: int, default: Any) -> Any:
        """fmi2Get<type>Status(kind), or ``default`` if the FMU does not provide it."""
        try:
            return getattr(self.slave, method)(kind)
        except Exception:  # noqa: BLE001 - optional in FMI 2.0 (fmi2Discard)
            return default
