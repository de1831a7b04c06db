"""Interrupts that keep what was done.

A SIGINT (Ctrl-C) or SIGTERM raised as ``KeyboardInterrupt`` lands inside whatever Python code
runs at that moment, usually an FMU's ``do_step`` behind the C API, where it becomes an opaque
"doStep failed" or a traceback. While :func:`guard` is active the signals only set a flag; the
master checks it between FMU calls (:func:`check`) and stops with :class:`Interrupted`, so the
partial results are written. A second signal exits at once with status 130, after ending the
processes registered with :func:`on_exit` (a run's or a sweep's children).
"""

from __future__ import annotations

import os
import signal
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager

EXIT_INTERRUPTED = 130
_SIGNALS = (signal.SIGINT, signal.SIGTERM)
_requested: list[str] = []  # names of the signals received while guarded
_at_exit: list[Callable[[], None]] = []  # what a second signal does before exiting


class Interrupted(Exception):  # noqa: N818 - the user's word for it
    """The run was stopped by SIGINT/SIGTERM; the message says where."""


def _handler(signum: int, _frame: object) -> None:
    if _requested:  # second signal: leave now, ending the children first
        for end in list(_at_exit):
            try:
                end()
            except Exception:  # noqa: BLE001, S110 - leaving regardless
                pass
        os.write(2, b"interrupted again: exiting at once\n")
        os._exit(EXIT_INTERRUPTED)
    _requested.append(signal.Signals(signum).name)


@contextmanager
def guard(restore: bool = True) -> Iterator[None]:
    """Turn SIGINT/SIGTERM into a flag for the duration (main thread only; elsewhere, and when
    already guarded, a no-op). The flag is cleared on entry. ``restore=False`` (the ``cosim
    run`` process) keeps the handlers afterwards, so a signal arriving while the process exits
    is not a traceback either."""
    if threading.current_thread() is not threading.main_thread() or _active:
        yield
        return
    previous = {sig: signal.getsignal(sig) for sig in _SIGNALS}
    _requested.clear()
    _active.append(True)
    try:
        for sig in _SIGNALS:
            signal.signal(sig, _handler)
        yield
    finally:
        if restore:
            for sig, old in previous.items():
                signal.signal(sig, old)
        _active.clear()


_active: list[bool] = []


def reset() -> None:
    """Forget any guard, signal and exit hook (a process forked from a guarded one)."""
    _active.clear()
    _requested.clear()
    _at_exit.clear()


def on_exit(end: Callable[[], None]) -> None:
    """Call ``end`` (e.g. kill the child processes) before a second signal exits."""
    if end not in _at_exit:
        _at_exit.append(end)


def requested() -> str | None:
    """The name of the signal received while guarded (``"SIGINT"``), or None."""
    return _requested[0] if _requested else None


def check_between(what: str) -> None:
    """Raise :class:`Interrupted` ("<what> interrupted") if a signal arrived."""
    if _requested:
        raise Interrupted(f"{what} interrupted ({_requested[0]})")


def check(t: float) -> None:
    """Raise :class:`Interrupted` ("interrupted at t = ... s") if a signal arrived."""
    if _requested:
        raise Interrupted(f"interrupted at t = {t:g} s ({_requested[0]})")
