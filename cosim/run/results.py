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
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

FILES = ("results.csv", "summary.json", "plot.png")


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


LOCK_FILE = ".cosim-run.lock"


@contextlib.contextmanager
def locked_destination(path: Path, option: str = "--out") -> Iterator[None]:
    """Hold an exclusive ``fcntl`` lock on ``path/.cosim-run.lock`` while a run writes into the
    folder ``path`` (created); a second run into the same folder meanwhile fails at once with
    :class:`OutputError` instead of one result silently replacing the other. The kernel drops
    the lock when the process ends, however it ends."""
    path = Path(path)
    try:
        path.mkdir(parents=True, exist_ok=True)
        handle = open(path / LOCK_FILE, "a+")  # noqa: SIM115 - held for the with-block
    except OSError as err:
        raise OutputError(f"{option} {path}: cannot write in it: {err.strerror or err}") from None
    with handle:
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise OutputError(f"{option} {path}: another cosim run is writing into this folder "
                              f"(it holds {path / LOCK_FILE}); wait for it to end or give "
                              "another --out") from None
        try:
            yield
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)


def _is_complete_run(out_dir: Path) -> bool:
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
                  force: bool = False) -> list[Path]:
    """Write results.csv, summary.json and (unless ``plot`` is False) plot.png into ``out_dir``
    (into ``<out_dir>.partial`` for a partial result when ``out_dir`` holds a complete run and
    ``force`` is False). Returns the paths written."""
    out_dir = Path(out_dir)
    if not result.summary.get("completed", True) and not force and _is_complete_run(out_dir):
        out_dir = out_dir.with_name(out_dir.name + ".partial")
    out_dir.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=".writing-", dir=out_dir))
    try:
        result.frame.to_csv(tmp / "results.csv", index=False)  # repr: round-trip exact
        (tmp / "summary.json").write_text(json.dumps(_json_safe(result.summary), indent=2)
                                          + "\n")
        if plot:
            plot_run(result, tmp / "plot.png")
        written = []
        for name in FILES:  # three renames: the window between them is microseconds
            if (tmp / name).exists():
                os.replace(tmp / name, out_dir / name)
                written.append(out_dir / name)
            elif name == "plot.png" and (out_dir / name).exists():
                (out_dir / name).unlink()  # a plot of another run must not stay next to these
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return written


def format_stop_error(error_m: float) -> str:
    """A stop error in cm under 1 m, otherwise in m."""
    return f"{error_m * 100:+.1f} cm" if abs(error_m) < 1.0 else f"{error_m:+.2f} m"


_UNIT_DISPLAY = {"N": (1e-3, "kN"), "m/s2": (1.0, "m/s²"), "%": (1.0, "%"),
                 "Pa": (1e-3, "kPa"), "W": (1e-3, "kW"), "m/s": (3.6, "km/h")}


def display_unit(unit: str | None) -> tuple[float, str | None]:
    """(scale, label) to plot a quantity declared in ``unit``: kN for N, m/s² for m/s2, ..."""
    if unit is None:
        return 1.0, None
    return _UNIT_DISPLAY.get(unit, (1.0, unit))


def variable_unit(scenario: Any, ref: str) -> str | None:
    """The declared unit of ``"instance.variable"`` from its FMU's modelDescription."""
    try:
        from fmpy import read_model_description

        comp, var = ref.split(".", 1)
        md = read_model_description(str(scenario.components[comp].fmu_path), validate=False)
        found = next(v for v in md.modelVariables if v.name == var)
        if found.unit:
            return found.unit
        return found.declaredType.unit if found.declaredType is not None else None
    except Exception:  # noqa: BLE001 - a plot label must never fail a run
        return None


def _stop_inset(ax: Any, pos: np.ndarray, speed_kmh: np.ndarray, stop: float,
                x_scale: float) -> None:
    """A zoom on the last 20 m before the stop point (speed vs position)."""
    near = pos >= stop - 20.0
    if not near.any() or len(pos) < 2:
        return
    inset = ax.inset_axes([0.40, 0.08, 0.28, 0.34])
    inset.set_facecolor("white")
    inset.set_zorder(10)
    inset.plot(pos[near] / x_scale, speed_kmh[near], color="C0", lw=1.0)
    inset.axvline(stop / x_scale, color="C3", lw=0.8, ls="-.")
    right = max(float(pos[near].max()), stop + 2.0)
    inset.set_xlim((stop - 20.0) / x_scale, right / x_scale)
    inset.set_title("last 20 m", fontsize=7)
    inset.tick_params(labelsize=6)
    inset.grid(True, alpha=0.3)


def plot_run(result: Any, path: Path) -> None:
    """Speed (and reference) vs position with the command on a second axis, as the papers'
    figures; coupler forces below when the scenario names them; otherwise outputs vs time."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from cosim.run.metrics import matching_columns

    cfg = result.scenario.summary
    frame = result.frame
    couplers = matching_columns(frame, cfg.get("coupler_forces"))
    rows = 2 if couplers else 1
    fig, axes = plt.subplots(rows, 1, figsize=(9, 4.5 * rows), squeeze=False)
    ax = axes[0][0]
    pos, speed = cfg.get("position"), cfg.get("speed")
    if frame.empty:
        ax.text(0.5, 0.5, "nothing recorded", ha="center", va="center",
                transform=ax.transAxes)
    elif pos in frame.columns and speed in frame.columns:
        x = frame[pos].to_numpy()
        xlabel = "position (m)"
        if np.nanmax(np.abs(x)) > 5000:
            x, xlabel = x / 1e3, "position (km)"
        ax.plot(x, frame[speed] * 3.6, label="speed", color="C0")
        for key, style, label in (("reference_speed", "--", "reference"),
                                  ("speed_limit", ":", "speed limit")):
            ref = cfg.get(key)
            if ref in frame.columns:
                ax.plot(x, frame[ref] * 3.6, style, label=label,
                        color="k" if key == "reference_speed" else "C3")
        ax.set_xlabel(xlabel)
        ax.set_ylabel("speed (km/h)")
        if "stop_point" in cfg:
            stop = float(cfg["stop_point"]) / (1e3 if xlabel.endswith("(km)") else 1.0)
            ax.axvline(stop, color="C3", lw=0.8, ls="-.", label="stop point")
        command = cfg.get("command")
        if command in frame.columns:
            ax2 = ax.twinx()
            scale, unit = display_unit(variable_unit(result.scenario, command))
            ax2.step(x, frame[command] * scale, where="post", color="C2", lw=1.0,
                     label="command")
            ax2.set_ylabel(f"command ({unit})" if unit else "command")
            lines = ax.get_legend_handles_labels()[0] + ax2.get_legend_handles_labels()[0]
            labels = ax.get_legend_handles_labels()[1] + ax2.get_legend_handles_labels()[1]
            ax.legend(lines, labels, loc="best", fontsize=8)
        else:
            ax.legend(loc="best", fontsize=8)
        if "stop_point" in cfg:  # on the topmost axes, opaque
            _stop_inset(ax.figure.axes[-1], frame[pos].to_numpy(),
                        frame[speed].to_numpy() * 3.6, float(cfg["stop_point"]),
                        1e3 if xlabel.endswith("(km)") else 1.0)
    else:
        t = frame["time"]
        for col in frame.columns[1:9]:
            ax.plot(t, frame[col], label=col)
        ax.set_xlabel("time (s)")
        ax.legend(loc="best", fontsize=8)
    summary = result.summary
    title = result.scenario.name
    if summary.get("stop_error_m") is not None:
        title += f"  stop error {format_stop_error(summary['stop_error_m'])}"
    if summary.get("command_switches") is not None:
        title += f"  switches {summary['command_switches']}"
    if not summary.get("completed", True):
        error = str(summary.get("error") or "failed")
        title += f"\nincomplete ({error if error.startswith('interrupted') else 'failed'})"
    ax.set_title(title)
    ax.grid(True, alpha=0.3)
    if couplers:
        axc = axes[1][0]
        t = frame["time"].to_numpy()
        forces = frame[couplers].to_numpy() / 1e3
        if len(couplers) <= 3:
            for i, col in enumerate(couplers):
                axc.plot(t, forces[:, i], lw=0.8, label=col.split(".", 1)[1])
        else:  # many couplers oscillating: one readable envelope, not a solid band of lines
            hi, lo = forces.max(axis=1), forces.min(axis=1)
            axc.fill_between(t, lo, hi, color="C0", alpha=0.25, lw=0,
                             label=f"range over {len(couplers)} couplers")
            axc.plot(t, hi, color="C3", lw=0.9, label="largest draft")
            axc.plot(t, lo, color="C2", lw=0.9, label="largest buff")
        axc.set_xlabel("time (s)")
        axc.set_ylabel("coupler force (kN)")
        axc.grid(True, alpha=0.3)
        axc.legend(loc="best", fontsize=7, ncol=3)
    fig.tight_layout()
    fig.savefig(path, dpi=110, format="png")
    plt.close(fig)
