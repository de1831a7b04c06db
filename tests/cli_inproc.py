"""``cosim ARGS`` in the pytest process, through typer's test runner: the exit code, stdout and
stderr a ``python -m cosim.cli`` process gives (``test_cli_messages.
test_no_help_text_is_cut_at_80_columns`` compares the two), without starting an interpreter.
For messages only; what concerns the process itself (its exit status as a process, signals,
its environment, locks another process holds, a forked run child's output) runs one."""

from __future__ import annotations

import signal

from typer.testing import CliRunner, Result

from cosim.cli import app

PROG = "python -m cosim.cli"
_SIGNALS = (signal.SIGINT, signal.SIGTERM)


def cosim_inproc(*args: str, env: dict[str, str] | None = None) -> Result:
    """``cosim ARGS`` in this process; ``env``: variables set for the call. The SIGINT/SIGTERM
    handlers ``cosim run`` installs (kept in its own process) are restored afterwards."""
    handlers = {sig: signal.getsignal(sig) for sig in _SIGNALS}
    try:
        return CliRunner().invoke(app, list(args), env=env, prog_name=PROG)
    finally:
        for sig, handler in handlers.items():
            signal.signal(sig, handler)


def no_traceback(result: Result) -> bool:
    """The command ended through its own exit (a message and a status), not an exception a
    process would print as a traceback."""
    return result.exception is None or isinstance(result.exception, SystemExit)
