"""Writing a run: ``results.csv`` (time series), ``summary.json`` and ``plot.png``
(:func:`cosim.run.figures.run.plot_run`).

The files are written into a temporary folder inside the destination and then renamed into
place, so an interrupted write never leaves a half-written result, or files of two runs, next
to each other. Partial results never replace a complete earlier run unless forced: they go to
``<out>.partial`` instead.
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import math
import os
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from cosim.run.columns import column_units
from cosim.run.figures.run import plot_run

PLOT_FORMATS = ("png", "svg", "pdf")
UNITS_FILE = "results.units.json"  # beside results.csv: column -> declared unit (or null)
FILES = ("results.csv", UNITS_FILE, "summary.json", *(f"plot.{fmt}" for fmt in PLOT_FORMATS))


class OutputError(ValueError):
    """An output destination that cannot be written; the message names the option and path."""


def check_destination(path: Path, option: str = "--out", is_dir: bool = True) -> None:
    """Fail before a run if ``path`` cannot become the output folder (or file, with
    ``is_dir=False``): it, or a parent, is a file, or the nearest existing folder is not
    writable (tried by creating and removing a file, which also holds for root)."""
    path = Path(path)
    if is_dir and path.exists() and not path.is_dir():
        raise OutputError(f"{option} {path}: is a file, not a folder")
    if not is_dir and path.is_dir():
        raise OutputError(f"{option} {path}: is a folder, not a file")
    parent = path if is_dir else path.parent
    existing = parent
    while not existing.exists():
        existing = existing.parent
    if not existing.is_dir():
        raise OutputError(f"{option} {path}: {existing} is a file, not a folder")
    try:
        fd, probe = tempfile.mkstemp(prefix=".cosim-probe-", dir=existing)
        os.close(fd)
        os.unlink(probe)
    except OSError as err:
        raise OutputError(f"{option} {path}: cannot write in {existing}: "
                          f"{err.strerror or err}") from None


LOCK_FILE = ".cosim.lock"  # in an output folder: the pid and command line of its writer


def lock_path(path: Path, is_dir: bool = True) -> Path:
    """The lock file of the output folder ``path`` (``path/.cosim.lock``), or of the output
    file ``path`` with ``is_dir=False`` (``.<name>.cosim.lock`` beside it)."""
    path = Path(path)
    return path / LOCK_FILE if is_dir else path.with_name(f".{path.name}{LOCK_FILE}")


def _holder(text: str) -> str:
    """The lock file's writer as the refusal names it: ``pid N: COMMAND``, and whether that
    process has ended (its forked workers, which share the lock, still hold it then)."""
    pid, _, command = text.strip().partition(" ")
    if not pid.isdigit():
        return "a process that has not yet written its pid"
    try:
        os.kill(int(pid), 0)
        alive = ""
    except ProcessLookupError:
        alive = "; it has ended, its worker processes still hold the lock"
    except PermissionError:  # another user's live process
        alive = ""
    return f"pid {pid}: {command}{alive}"


@contextlib.contextmanager
def locked_destination(path: Path, option: str = "--out", is_dir: bool = True) -> Iterator[None]:
    """Hold an exclusive ``fcntl`` lock on :func:`lock_path` while a command writes into the
    folder ``path`` (created; with ``is_dir=False`` the file ``path``, its folder created), the
    lock file naming this process (``PID COMMAND LINE``). A second command into the same
    destination meanwhile fails at once with :class:`OutputError` naming the destination and
    the holder, instead of one result silently replacing the other. The kernel drops the lock
    when its holder ends, however it ends: a lock left by a killed command is taken over."""
    import shlex
    import sys

    path = Path(path)
    lock = lock_path(path, is_dir)
    try:
        lock.parent.mkdir(parents=True, exist_ok=True)
        handle = open(lock, "a+")  # noqa: SIM115 - held for the with-block
    except OSError as err:
        raise OutputError(f"{option} {path}: cannot write in it: {err.strerror or err}") from None
    with handle:
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            handle.seek(0)
            what = "this folder" if is_dir else "this file"
            raise OutputError(f"{option} {path}: another cosim command is writing into {what} "
                              f"({_holder(handle.read())}; it holds {lock}); wait for it to "
                              f"end or give another {option}") from None
        try:
            handle.truncate(0)
            handle.write(f"{os.getpid()} {shlex.join(sys.argv)}\n")
            handle.flush()
            yield
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)


def is_complete_run(out_dir: Path) -> bool:
    try:
        return json.loads((out_dir / "summary.json").read_text()).get("completed") is True
    except (OSError, ValueError, AttributeError):
        return False


def _json_safe(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {str(k): _json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_json_safe(v) for v in obj]
    if isinstance(obj, (np.floating, float)):
        return float(obj) if math.isfinite(obj) else None
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.bool_):
        return bool(obj)
    return obj


def write_results(result: Any, out_dir: Path, plot: bool = True,
                  force: bool = False, plot_format: str = "png") -> list[Path]:
    """Write results.csv, its units (``results.units.json``: column -> the unit its FMU
    declares, null where none), summary.json and (unless ``plot`` is False) the plot
    (``plot.<plot_format>``: png, svg or pdf) into ``out_dir``
    (into ``<out_dir>.partial`` for a partial result when ``out_dir`` holds a complete run and
    ``force`` is False). Returns the paths written."""
    out_dir = Path(out_dir)
    if plot_format not in PLOT_FORMATS:
        raise ValueError(f"plot format {plot_format!r}: one of {', '.join(PLOT_FORMATS)}")
    if not result.summary.get("completed", True) and not force and is_complete_run(out_dir):
        out_dir = out_dir.with_name(out_dir.name + ".partial")
    out_dir.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=".writing-", dir=out_dir))
    try:
        result.frame.to_csv(tmp / "results.csv", index=False)  # repr: round-trip exact
        units = column_units(getattr(result, "scenario", None), result.frame.columns)
        (tmp / UNITS_FILE).write_text(json.dumps(units, indent=2, ensure_ascii=False) + "\n",
                                      encoding="utf-8")
        (tmp / "summary.json").write_text(json.dumps(_json_safe(result.summary), indent=2)
                                          + "\n")
        if plot:
            plot_run(result, tmp / f"plot.{plot_format}")
        written = []
        for name in FILES:  # a few renames: the window between them is microseconds
            if (tmp / name).exists():
                os.replace(tmp / name, out_dir / name)
                written.append(out_dir / name)
            elif name.startswith("plot.") and (out_dir / name).exists():
                (out_dir / name).unlink()  # a plot of another run must not stay next to these
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return written
