"""Runs in a child process, so that an FMU that crashes or hangs cannot take the run with it.

A :class:`Child` runs one module-level function in a process of its own (forked on Linux, so it
starts with the parent's imports and extracted FMUs; spawned elsewhere) and hands back its
return value or the exception it raised. The child

* dies with its parent (``prctl(PR_SET_PDEATHSIG, SIGKILL)`` on Linux, a thread watching the
  parent's process id elsewhere), so a ``kill -9`` of the parent leaves no process behind;
* sits in a process group of its own, so a Ctrl-C at the terminal reaches the parent alone,
  which passes it on once (:meth:`Child.interrupt`);
* keeps a breadcrumb of the FMU call it is in (:func:`watch`: the instance, the FMI function
  and the simulated time, written into shared memory on entry and cleared on return), so the
  parent can say where it crashed (:meth:`Child.crash_message`: "FMU plant crashed with
  SIGSEGV in fmi2DoStep at t = 3.2 s") or where it hangs.
"""

from __future__ import annotations

import atexit
import contextlib
import ctypes
import multiprocessing
import os
import signal
import sys
import threading
import time
from collections.abc import Callable
from multiprocessing.connection import Connection
from multiprocessing.connection import wait as wait_any
from typing import Any

from cosim.run import interrupt

# the FMU calls the breadcrumb names: Unit method -> FMI function name after the prefix
CALLS = (("instantiate", "Instantiate"), ("enter_initialization", "EnterInitializationMode"),
         ("exit_initialization", "ExitInitializationMode"), ("_do_step", "DoStep"),
         ("terminate", "Terminate"), ("free", "FreeInstance"))
_IDLE = -1.0  # breadcrumb slot 1 outside any call
_PR_SET_PDEATHSIG = 1  # linux/prctl.h

_LABEL_BYTES = 8192  # room for the watched instances' names
# this process's breadcrumb (a child's): [instance index, call index or _IDLE, t (s)], and
# the watched instances as "name prefix" lines, by index
_crumb: Any = None
_labels: Any = None
_names: list[str] = []
_live: dict[int, Any] = {}  # this process's running children by process id
FORK = sys.platform == "linux" and "fork" in multiprocessing.get_all_start_methods()


class ChildFailed(Exception):
    """The child process ended without a result (a crash, or killed); the message says how
    and in which FMU call."""


def watch(units: list[Any]) -> None:
    """In a child: record every FMU call of ``units`` (see the module doc); elsewhere
    nothing. Each call costs one shared-memory write on entry and one on return. A unit
    watched again (an instance a pool kept for the next job) is traced from its own methods,
    not from the previous job's tracing: one wrapper per call, however many jobs."""
    if _crumb is None:
        return
    for unit in units:
        index = len(_names)
        unit.crumb_index = index  # the C loop's breadcrumb (cosim.run.master.native_loop)
        _names.append(f"{unit.name} {getattr(unit, 'C_PREFIX', '') or 'fmi2'}")
        for code, (method, _) in enumerate(CALLS):
            call = getattr(unit, method)
            setattr(unit, method, _traced(getattr(call, "__wrapped__", call), unit, index, code))
    text = "\n".join(_names).encode()[:_LABEL_BYTES - 1]
    _labels[:len(text) + 1] = text + b"\0"


def _traced(call: Callable[..., Any], unit: Any, index: int, code: int) -> Callable[..., Any]:
    crumb = _crumb
    stepping = CALLS[code][0] == "_do_step"

    def traced(*args: Any, **kwargs: Any) -> Any:
        ticks = args[0] if stepping else unit.time_ticks
        crumb[0:3] = (index, code, ticks * 1e-9)
        try:
            return call(*args, **kwargs)
        finally:
            crumb[1] = _IDLE

    traced.__wrapped__ = call  # type: ignore[attr-defined]
    return traced


def die_with_parent(parent: int) -> None:
    """End this process when the process ``parent`` ends (however it ends)."""
    if sys.platform == "linux":
        with contextlib.suppress(OSError, AttributeError):
            libc = ctypes.CDLL(None, use_errno=True)
            if libc.prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0) == 0:
                if os.getppid() != parent:  # it ended before the request took effect
                    os._exit(1)
                return

    def check() -> None:
        while os.getppid() == parent:
            time.sleep(0.5)
        os._exit(1)

    threading.Thread(target=check, daemon=True, name="parent-watch").start()


def _child_main(conn: Connection, crumb: Any, labels: Any, parent: int,
                setup: Callable[[], None] | None, first: Any) -> None:
    """A child's life: ``setup()``, then the job ``first`` (if any) and each job
    ``(function, args, kwargs)`` received run and its outcome sent back, until None (or the
    parent's end)."""
    global _crumb, _labels
    die_with_parent(parent)
    os.setpgrp()  # the terminal's Ctrl-C reaches the parent, which passes it on
    interrupt.reset()
    _crumb, _labels = crumb, labels
    if setup is not None:
        setup()
    while True:
        try:
            job, first = first or conn.recv(), None
        except (EOFError, OSError):
            break
        if job is None:
            break
        function, args, kwargs = job
        _names.clear()
        # SIGINT/SIGTERM set a flag, checked between FMU calls; the handlers stay between
        # jobs, so a late signal is no traceback (the flag is cleared at the next job)
        with interrupt.guard(restore=False):
            try:
                outcome: tuple[str, Any] = ("ok", function(*args, **kwargs))
            except BaseException as err:  # noqa: BLE001 - handed to the parent, raised there
                outcome = ("raised", err)
        try:
            conn.send(outcome)
        except Exception as err:  # noqa: BLE001 - e.g. a result that does not pickle
            conn.send(("raised", RuntimeError(f"{type(err).__name__}: {err}")))
    conn.close()


class Child:
    """A child process (see the module doc) that runs jobs given with :meth:`submit`, one at
    a time; ``setup()`` runs in it first, then ``first`` (a job as :meth:`submit` takes it:
    ``(function, args, kwargs)``, handed over by the fork: its arguments need not pickle).
    Forked on Linux, spawned elsewhere (then it inherits this process's environment, and
    jobs and results are pickled)."""

    def __init__(self, setup: Callable[[], None] | None = None, spawn: bool = False,
                 first: tuple[Callable[..., Any], tuple[Any, ...], dict[str, Any]] | None
                 = None) -> None:
        ctx = multiprocessing.get_context("fork" if FORK and not spawn else "spawn")
        self.crumb = ctx.RawArray(ctypes.c_double, 3)
        self.crumb[1] = _IDLE
        self.labels = ctx.RawArray(ctypes.c_char, _LABEL_BYTES)
        self.conn, child_conn = ctx.Pipe()
        self.process = ctx.Process(target=_child_main,
                                   args=(child_conn, self.crumb, self.labels, os.getpid(),
                                         setup, first))
        self.process.start()
        _live[self.pid] = self
        interrupt.on_exit(kill_all)
        child_conn.close()
        self.started = time.monotonic()
        self.outcome: tuple[str, Any] | None = None
        self.busy = first is not None
        self.stuck_since: float | None = None  # when the last interrupt was passed on

    def submit(self, function: Callable[..., Any], args: tuple[Any, ...] = (),
               kwargs: dict[str, Any] | None = None) -> Child:
        """Run ``function(*args, **kwargs)`` in the child."""
        self.outcome, self.busy, self.stuck_since = None, True, None
        self.started = time.monotonic()
        self.crumb[1] = _IDLE
        try:
            self.conn.send((function, args, kwargs or {}))
        except BaseException:
            self.kill()
            raise
        return self

    def close(self) -> None:
        """Let the child end (killed when it does not within seconds)."""
        with contextlib.suppress(OSError):
            self.conn.send(None)
        self.process.join(10.0)
        if self.process.is_alive():
            self.kill()
        _live.pop(self.pid, None)

    @property
    def pid(self) -> int:
        return self.process.pid or 0

    def waitables(self) -> list[Any]:
        return [self.conn, self.process.sentinel]

    def poll(self) -> bool:
        """Has the job ended, with a result or with the child? Takes the result when
        there."""
        if self.outcome is None and self.conn.poll():
            try:
                self.outcome = self.conn.recv()
            except (EOFError, OSError):
                pass
        if self.outcome is not None:
            self.busy = False
            return True
        if self.process.is_alive():
            return False
        self.process.join()
        _live.pop(self.pid, None)
        return True

    def result(self) -> Any:
        """The function's return value; its exception raised here; :class:`ChildFailed`
        when the child ended without either."""
        if self.outcome is None:
            self.process.join()
            raise ChildFailed(self.crash_message())
        kind, value = self.outcome
        self.outcome = None
        if kind == "raised":
            raise value
        return value

    def in_call(self) -> str | None:
        """``fmi2DoStep at t = 3.2 s`` of instance ``plant`` while the child is in an FMU
        call (``FMU plant ... in fmi2DoStep at t = 3.2 s``), else None."""
        index, code, t = self.crumb[0], self.crumb[1], self.crumb[2]
        if code == _IDLE:
            return None
        names = self.labels.value.decode(errors="replace").split("\n")
        name, _, prefix = (names[int(index)] if int(index) < len(names)
                           else f"#{int(index)} fmi2").partition(" ")
        return f"FMU {name}|{prefix}{CALLS[int(code)][1]} at t = {t:g} s"

    def crash_message(self) -> str:
        """How the child ended: the signal or exit status, and the FMU call it was in."""
        code = self.process.exitcode
        if code is not None and code < 0:
            how = f"crashed with {signal.Signals(-code).name}"
        else:
            how = f"exited with status {code}"
        where = self.in_call()
        if where is None:
            return f"the run's process {how} outside any FMU call"
        fmu, call = where.split("|")
        return f"{fmu} {how} in {call}"

    def interrupt(self, name: str) -> None:
        """Pass the signal ``name`` (SIGINT, SIGTERM) on: the run stops at its next
        communication point."""
        self.stuck_since = time.monotonic()
        with contextlib.suppress(OSError):
            os.kill(self.pid, getattr(signal, name, signal.SIGINT))

    def kill(self) -> None:
        """End the child at once (SIGKILL) and reap it."""
        with contextlib.suppress(OSError):
            os.kill(self.pid, signal.SIGKILL)
        self.process.join(10.0)
        _live.pop(self.pid, None)


def kill_all() -> None:
    """SIGKILL every running child of this process (a second signal, or this process's
    exit: none is left waiting for work)."""
    for pid in list(_live):
        with contextlib.suppress(OSError):
            os.kill(pid, signal.SIGKILL)


atexit.register(kill_all)  # before multiprocessing's own exit handler, which joins them


_POLL_S = 0.1  # s between looks at the children
STOP_GRACE_S = 3.0  # s an FMU call may take to return once an interrupt was passed on


def hung(child: Child) -> str | None:
    """After an interrupt was passed on: the FMU call that has not returned for
    :data:`STOP_GRACE_S` (``FMU plant did not return from fmi2DoStep at t = 3.2 s``), else
    None."""
    if child.stuck_since is None or time.monotonic() - child.stuck_since < STOP_GRACE_S:
        return None
    where = child.in_call()
    if where is None:
        child.stuck_since = time.monotonic()  # it left the call: still stopping
        return None
    fmu, call = where.split("|")
    return f"{fmu} did not return from {call}"


def wait(children: list[Child], timeout: float) -> None:
    """Until one of ``children`` has a result or ends, or ``timeout`` seconds passed."""
    waitables = [w for c in children for w in c.waitables()]
    if waitables:
        wait_any(waitables, timeout)
    else:
        time.sleep(timeout)


def supervise(child: Child, poll_s: float = _POLL_S) -> Any:
    """Wait for ``child``'s result, passing a signal received here
    (:mod:`cosim.run.interrupt`) to it once; an FMU call that does not return within
    :data:`STOP_GRACE_S` of that ends the child (:class:`cosim.run.interrupt.Interrupted`
    naming the call). Returns the function's value or raises its exception, or
    :class:`ChildFailed` when the child ended without either."""
    while not child.poll():
        wait([child], poll_s)
        name = interrupt.requested()
        if name is not None and child.stuck_since is None:
            child.interrupt(name)
        if (stuck := hung(child)) is not None:
            child.kill()
            raise interrupt.Interrupted(f"{stuck} after {name}: stopped it (SIGKILL); "
                                        "nothing this run recorded could be kept")
    return child.result()
