"""One BLAS thread inside each run (threadpoolctl).

The controllers' linear algebra is on matrices of a few dozen rows; OpenBLAS would still start a
second thread on each call and keep it spinning, so one run already kept two cores busy and
parallel sweep workers slow each other down. :func:`one_blas_thread` limits every
BLAS library loaded in the process to one thread for the duration of a run and restores the
previous limits afterwards; its ``refresh`` also limits libraries loaded meanwhile (an FMU's
bundled modules importing SciPy at instantiation).

Finding the libraries means walking every loaded shared object (milliseconds), so the scan is
cached and repeated only when ``sys.modules`` has grown since (native libraries are loaded by
imports); setting and restoring the limits of known libraries costs microseconds.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Iterator
from contextlib import ExitStack, contextmanager
from typing import Any

_scan: dict[str, Any] = {"controller": None, "modules": -1}


def _controller() -> Any:
    """A ``ThreadpoolController`` of the libraries loaded now (cached, see module doc)."""
    from threadpoolctl import ThreadpoolController

    if _scan["controller"] is None or len(sys.modules) != _scan["modules"]:
        _scan["controller"] = ThreadpoolController()
        _scan["modules"] = len(sys.modules)
    return _scan["controller"]


@contextmanager
def one_blas_thread() -> Iterator[Callable[[], None]]:
    """Limit BLAS to one thread until exit; yields ``refresh()`` (limit libraries loaded since
    the start too). Limits are restored in reverse order on exit."""
    with ExitStack() as stack:

        def limit() -> None:
            controller = _controller()
            if controller is not getattr(limit, "done", None):
                stack.callback(controller.limit(limits=1, user_api="blas")
                               .restore_original_limits)
                limit.done = controller  # type: ignore[attr-defined]

        limit()
        yield limit


def limit_blas_for_process() -> None:
    """Limit BLAS to one thread for the rest of the process (a sweep worker)."""
    _controller().limit(limits=1, user_api="blas")
