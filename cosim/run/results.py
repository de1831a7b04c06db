"""Writing a run: ``results.csv`` (time series), ``summary.json`` and ``plot.png``.

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
import textwrap
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from cosim.run.columns import axis_label, column_units, display_unit, is_held, variable_info
from cosim.run.figures import PLOT_DPI, reference_curve
from cosim.run.metrics import matching_columns

PLOT_FORMATS = ("png", "svg", "pdf")
MAX_CM_DECIMALS = 6  # a stop error is written to 0.01 um at finest
LABEL_WIDTH = 40  # characters per line of an axis label
LEGEND_DROP = 0.5  # in, from an axes' bottom edge to the top of the legend under it
INSET_LEFT = 1.27  # axes widths, the stop inset's left edge (clear of a one-line twin label)
INSET_LEFT_PER_LINE = 0.04  # axes widths further right per further line of the twin's label
# Line styles of the run figure: what was measured solid and wide, what it tracks thinner, in
# black (as the controller holds it) and grey (the continuous curve it samples).
# Drawn over the measured curve, a thin reference stays visible where the two coincide.
MEASURED = {"color": "C0", "ls": "-", "lw": 2.0, "zorder": 2}
REFERENCE = {"color": "k", "ls": "-", "lw": 0.8, "zorder": 3}
REFERENCE_CURVE = {"color": "0.5", "ls": "-", "lw": 0.8, "zorder": 3}
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


def format_stop_error(error_m: float) -> str:
    """A stop error in m from 1 m up (two decimals), in cm below: one decimal from 0.1 cm
    up, two significant digits below that (so a sub-millimetre error is not shown as 0.0);
    an error that rounds to zero is written unsigned (never ``-0.0``)."""
    if abs(error_m) >= 1.0:
        return f"{error_m:+.2f} m"
    cm = error_m * 100.0
    decimals = 1 if abs(cm) >= 0.1 or cm == 0.0 else min(1 - math.floor(math.log10(abs(cm))),
                                                       MAX_CM_DECIMALS)
    text = f"{cm:+.{decimals}f}"
    return f"{text.lstrip('+-')} cm" if float(text) == 0.0 else f"{text} cm"


def _stop_inset(ax: Any, pos: np.ndarray, speed_kmh: np.ndarray, stop: float,
                label_lines: int = 1) -> Any:
    """A zoom on the last 20 m before the stop point: speed against the distance to the stop
    point in metres (plain numbers, no offset), right of the axes (and of a twin axis's
    labels, ``label_lines`` lines of them), where it covers no curve; the legend is outside the
    axes."""
    from matplotlib.ticker import MaxNLocator

    near = pos >= stop - 20.0
    if not near.any() or len(pos) < 2:
        return None
    inset = ax.inset_axes([INSET_LEFT + INSET_LEFT_PER_LINE * (label_lines - 1), 0.25, 0.28, 0.6])
    inset.set_facecolor("white")
    inset.set_zorder(10)
    inset.plot(pos[near] - stop, speed_kmh[near], color=MEASURED["color"], lw=1.0)
    inset.axvline(0.0, color="C3", lw=0.8, ls="-.")
    right = max(float(pos[near].max()) - stop, 2.0)
    inset.set_xlim(-20.0, right)
    inset.set_xlabel("to stop point (m)", fontsize=7)
    inset.set_ylabel("speed (km/h)", fontsize=7)
    inset.set_title("last 20 m", fontsize=7)
    inset.tick_params(labelsize=6)
    inset.ticklabel_format(useOffset=False, style="plain")
    inset.xaxis.set_major_locator(MaxNLocator(5))
    inset.grid(True, alpha=0.3)
    return inset


def fit_band(ax: Any, values: Any, lo: float, hi: float, zoom: float = 0.2) -> bool:
    """Draw the band [lo, hi] (dotted lines) on ``ax`` and fit the y axis: the band and the
    data when the data reach beyond ``zoom`` of the band's half width, else the data alone
    (with a note that the band lies outside the view), so sub-band results are not flat
    lines. Returns True when zoomed in."""
    data = np.asarray(values, dtype=float)
    data = data[np.isfinite(data)]
    for edge in (lo, hi):
        ax.axhline(edge, color="red", linestyle=":", linewidth=1)
    half = 0.5 * (hi - lo)
    if data.size and np.max(np.abs(data - 0.5 * (lo + hi))) < zoom * half:
        span = max(float(data.max() - data.min()), 1e-4 * half)
        ax.set_ylim(float(data.min()) - 0.15 * span, float(data.max()) + 0.15 * span)
        ax.text(0.01, 0.98, f"band [{lo:g}, {hi:g}] outside the view", transform=ax.transAxes,
                va="top", fontsize=7, color="red")
        return True
    top = max(hi, float(data.max()) if data.size else hi)
    bottom = min(lo, float(data.min()) if data.size else lo)
    pad = 0.05 * (top - bottom)
    ax.set_ylim(bottom - pad, top + pad)
    return False


def legend_below(ax: Any, handles: list[Any], labels: list[str]) -> Any:
    """The legend under the axes, ``LEGEND_DROP`` below their bottom edge (clear of the tick
    labels and the x label; outside the axes: no curve, inset or twin axis can cover it)."""
    from matplotlib.transforms import ScaledTranslation

    below = ax.transAxes + ScaledTranslation(0.0, -LEGEND_DROP, ax.figure.dpi_scale_trans)
    return ax.legend(handles, labels, loc="upper center", bbox_to_anchor=(0.5, 0.0),
                     bbox_transform=below, ncol=min(len(labels), 4), fontsize=8,
                     frameon=False)


def plot_run(result: Any, path: Path) -> None:
    """:func:`draw_run` saved to ``path`` (its suffix: png at ``PLOT_DPI``, svg or pdf)."""
    import matplotlib.pyplot as plt

    fig = draw_run(result)
    fig.savefig(path, dpi=PLOT_DPI, format=Path(path).suffix.lstrip(".") or "png",
                bbox_inches="tight")
    plt.close(fig)


def wrapped_label(text: str) -> str:
    """An axis label broken into lines of at most ``LABEL_WIDTH`` characters, so a long
    declared description stays within its axes' height (clear of the title)."""
    return textwrap.fill(text, LABEL_WIDTH, break_long_words=False)


def _draw_tracking(result: Any, ax: Any, error_ax: Any | None) -> None:
    """Speed vs position on ``ax``: the measured speed solid and wide, the reference as its
    continuous curve over it (black, thinner; steps where the controller holds it, with the
    curve it samples in grey), the speed limit dotted, the stop point, the command on a twin
    axis and the last 20 m in an inset; ``reference - measured`` on ``error_ax`` below (shared
    x), and the legend under the lowest of the two."""
    cfg, frame = result.scenario.summary, result.frame
    pos, speed = cfg["position"], cfg["speed"]
    x = frame[pos].to_numpy(dtype=float)
    xlabel = "position (m)"
    if np.nanmax(np.abs(x)) > 5000:
        x, xlabel = x / 1e3, "position (km)"
    v_kmh = frame[speed].to_numpy(dtype=float) * 3.6
    ax.plot(x, v_kmh, label="speed", **MEASURED)
    reference = None
    ref = cfg.get("reference_speed")
    if ref in frame.columns:
        held = is_held(result.scenario, ref)
        reference = frame[ref].to_numpy(dtype=float) * 3.6
        ax.plot(x, reference, label="reference" + (" (as held by the controller)" if held
                                                   else ""),
                drawstyle="steps-post" if held else "default", **REFERENCE)
        curve = reference_curve(result.scenario, frame, ref) if held else None
        if curve is not None:  # the stopping curve itself, beside what was held
            reference = curve * 3.6
            ax.plot(x, reference, label="reference curve", **REFERENCE_CURVE)
    limit = cfg.get("speed_limit")
    if limit in frame.columns:
        ax.plot(x, frame[limit] * 3.6, ":", color="C3", lw=1.0, label="speed limit",
                drawstyle="steps-post" if is_held(result.scenario, limit) else "default")
    ax.set_ylabel("speed (km/h)")
    ax.ticklabel_format(useOffset=False, style="plain")
    stop = None
    if "stop_point" in cfg:
        stop = float(cfg["stop_point"]) / (1e3 if xlabel.endswith("(km)") else 1.0)
        ax.axvline(stop, color="C3", lw=0.8, ls="-.", label="stop point")
    handles, labels = ax.get_legend_handles_labels()
    top = ax
    command = cfg.get("command")
    if command in frame.columns:
        top = ax.twinx()
        text, unit = variable_info(result.scenario, command)
        top.plot(x, frame[command] * display_unit(unit)[0], color="C2", lw=1.0, label=text,
                 drawstyle="steps-post" if is_held(result.scenario, command) else "default")
        top.set_ylabel(wrapped_label(axis_label(text, unit)))
        top.ticklabel_format(useOffset=False, style="plain")
        more, more_labels = top.get_legend_handles_labels()
        handles, labels = handles + more, labels + more_labels
    ax.set_zorder(top.get_zorder() + 1)  # the speed curves above the command's
    ax.patch.set_visible(False)
    if stop is not None:  # on the topmost axes, opaque
        _stop_inset(ax, frame[pos].to_numpy(), v_kmh, float(cfg["stop_point"]),
                    top.get_ylabel().count("\n") + 1 if top is not ax else 1)
    lowest = ax
    if error_ax is not None and reference is not None:
        error_ax.plot(x, reference - v_kmh, label="reference − speed", **MEASURED)
        error_ax.axhline(0.0, color="0.3", lw=0.6)
        if stop is not None:
            error_ax.axvline(stop, color="C3", lw=0.8, ls="-.")
        error_ax.set_ylabel("reference − speed\n(km/h)")
        error_ax.ticklabel_format(useOffset=False, style="plain")
        error_ax.grid(True, alpha=0.3)
        ax.tick_params(labelbottom=False)
        lowest = error_ax
    lowest.set_xlabel(xlabel)
    legend_below(lowest, handles, labels)


def draw_run(result: Any) -> Any:
    """The run's figure: speed and reference vs position with the command on a second axis
    and the tracking error (reference minus speed) in a panel under it, as the papers'
    figures; coupler forces below when the scenario names them; otherwise outputs vs time.
    Curves and axes are labelled with the declared descriptions and units; outputs of sampled
    or self-triggered FMUs (held between events) are drawn as steps."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cfg = result.scenario.summary
    frame = result.frame
    couplers = matching_columns(frame, cfg.get("coupler_forces"))
    pos, speed = cfg.get("position"), cfg.get("speed")
    tracking = not frame.empty and pos in frame.columns and speed in frame.columns
    error = tracking and cfg.get("reference_speed") in frame.columns
    groups = [5.5 if error else 4.0] + ([3.5] if couplers else [])
    fig = plt.figure(figsize=(9, sum(groups) + 1.0 * len(groups)), layout="constrained")
    grid = fig.add_gridspec(len(groups), 1, height_ratios=groups)
    top = grid[0].subgridspec(2, 1, height_ratios=[3.0, 1.2]) if error else grid
    ax = fig.add_subplot(top[0])
    if frame.empty:
        ax.text(0.5, 0.5, "nothing recorded", ha="center", va="center",
                transform=ax.transAxes)
    elif tracking:
        _draw_tracking(result, ax, fig.add_subplot(top[1], sharex=ax) if error else None)
    else:
        t = frame["time"]
        units = set()
        for col in frame.columns[1:9]:
            text, unit = variable_info(result.scenario, col)
            scale = display_unit(unit)[0]
            units.add(display_unit(unit)[1])
            ax.plot(t, frame[col] * scale, label=axis_label(text, unit),
                    drawstyle="steps-post" if is_held(result.scenario, col) else "default")
        ax.set_xlabel("time (s)")
        if len(units) == 1 and None not in units:
            ax.set_ylabel(units.pop())
        ax.ticklabel_format(useOffset=False, style="plain")
        legend_below(ax, *ax.get_legend_handles_labels())
    summary = result.summary
    title = result.scenario.name
    if summary.get("stop_error_m") is not None:
        title += f"  stop error {format_stop_error(summary['stop_error_m'])}"
    if summary.get("command_switches") is not None:
        title += f"  switches {summary['command_switches']}"
    if not summary.get("completed", True):
        error_text = str(summary.get("error") or "failed")
        title += ("\nincomplete ("
                  f"{error_text if error_text.startswith('interrupted') else 'failed'})")
    ax.set_title(title)
    ax.grid(True, alpha=0.3)
    if couplers:
        axc = fig.add_subplot(grid[-1])
        t = frame["time"].to_numpy()
        forces = frame[couplers].to_numpy() / 1e3
        if len(couplers) <= 3:
            for i, col in enumerate(couplers):
                axc.plot(t, forces[:, i], lw=0.8, label=variable_info(result.scenario, col)[0])
        else:  # many couplers oscillating: one readable envelope, not a solid band of lines
            hi, lo = forces.max(axis=1), forces.min(axis=1)
            axc.fill_between(t, lo, hi, color="C0", alpha=0.25, lw=0,
                             label=f"range over {len(couplers)} couplers")
            axc.plot(t, hi, color="C3", lw=0.9, label="largest draft")
            axc.plot(t, lo, color="C2", lw=0.9, label="largest buff")
        axc.set_xlabel("time (s)")
        axc.set_ylabel("coupler force (kN)")
        axc.grid(True, alpha=0.3)
        axc.ticklabel_format(useOffset=False, style="plain")
        legend_below(axc, *axc.get_legend_handles_labels())
    return fig
